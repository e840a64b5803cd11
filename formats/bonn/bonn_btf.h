// Bonn binary .btf files: DFMF, FMF, PVF and BDI (btfc specification, formats chapter section 2.2; the
// byte layouts are pinned in docs/FORMAT.md, "Bonn .btf files").
//
// Reading: every format opens *as a Model* (codecs/codec.h), so info / eval / decompress /
// compare / re-compress work the same as on a .btfc model:
//   !DFMF08FCR            -> an `fmf` model, per-channel blocks y/u/v with the file's colour model
//   !FMF12FCER, !FMF06FC[R] -> an `fmf` model, one "rgb" block (rows = c + nC*(l + nL*v))
//   !PVF06FC[R]           -> a read-only per-view PCA model (factors held in memory)
//   !BDIF06R2!            -> a read-only model that reads texels from the file on demand
//                            (uncompressed, sparse, or bzip2 chunks), so memory stays bounded.
// Decoding in texel blocks (DecodeRequest with a region) bounds memory for all of them.
//
// Contracts:
//  - Little-endian, as every public reader (formats.md 2.2). Signatures match longest-first.
//  - Every count is checked against the bytes left in the file *before* anything is allocated;
//    products are overflow-checked. A file whose sizes disagree with each other, with the
//    meta block's struct_size, or that has trailing bytes is corrupt_data. Errors name the file
//    and the field, e.g. "carpet.btf: DFMF channel 1 SxV (4225000000 x 100 half) exceeds the
//    file (...)". Colour models 2, 5, 6, version >= 3 FMF headers and the transposed FMF/PVF
//    "images stacked" layouts that btfc does not decode answer `unsupported`.
//  - Rows: texel (x, y) is column x, row y *as stored* (texel index x + width*y); btfc does not
//    flip rows (Bonn's btf.hh flips y <-> H-1-y on load; see docs/FORMAT.md).
//  - Directions: (theta, phi) radians -> unit vectors; the light list is stored once per view
//    and must be identical for every view. Sets equal (within 0.5 deg) to the UBO2014 Dome 1
//    sampling are named "ubo2014" (BonnInfo::dome1).
//  - Writers write "<path>.tmp-<pid>" and rename; on failure nothing is left behind.
//  - Models are safe for concurrent const calls (eval, decode).
#pragma once
#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "codecs/codec.h"
#include "core/btf.h"

namespace btfc {

enum class BonnKind { dfmf, fmf, pvf, bdi };
const char* bonn_kind_name(BonnKind k);  // "DFMF", "FMF", "PVF", "BDI"

// The meta block (BTFLIB read_meta_data.m).
struct BonnMeta {
  uint32_t struct_version = 4;
  std::string measurement_setup, image_sensor, light_source;  // char[80] each, trailing NULs dropped
  float ppmm = 0;                                              // pixels per mm
  float rgb_scale_factor[3] = {1, 1, 1};
  uint32_t cosine_flag = 0;                   // version >= 2: cos(theta_l) already in the data
  std::string xml;                            // version >= 3
  std::vector<std::string> channel_names;     // version >= 4; else {"R","G","B"}
};

struct BonnInfo {
  std::string path;
  std::string signature;  // e.g. "!DFMF08FCR"
  BonnKind kind = BonnKind::dfmf;
  BonnMeta meta;
  BtfDesc desc;           // lights / views named "ubo2014" when they are Dome 1
  bool dome1 = false;     // both direction sets match UBO2014 Dome 1
  double dome1_max_dev_deg = -1;  // largest angle to the Dome 1 direction of the same index (-1: not 151)
  std::vector<std::array<float, 9>> rotations;  // row-major 3x3 each
  uint64_t file_size = 0;
  int color_model = -1;            // DFMF: as stored; FMF: 0, or 12 with dynamic range reduction
  std::vector<int> scalar_sizes;   // per stored block (DFMF channel, FMF matrix, PVF view)
  std::vector<int> components;     // per stored block
  int bdi_compression = -1;        // BDI: 0 full, 1 full bzip2, 2 sparse
  uint32_t bdi_scan_lines_per_chunk = 0;
  uint64_t bdi_stored_texels = 0;
  // Human-readable facts for `btfc info` (signature, colour model, precision, ranks, Dome 1...).
  std::vector<std::pair<std::string, std::string>> notes() const;
};

// True when the file starts with a known Bonn signature, or with the placeholder of an unfinished
// btfc working file (bdi_work.h; opening it then fails naming that). Reads 10 bytes; no errors.
bool is_bonn_btf(const std::string& path);

// Parses and validates the whole structure (every header, every size against the file, the
// trailing-bytes rule) without reading the bulk data.
Result<BonnInfo> read_bonn_info(const std::string& path);

// Opens any Bonn file as a model (see the top of this file). `info` (optional) receives the
// header facts. DFMF/FMF/PVF read their factors into memory; BDI reads on demand.
Result<std::unique_ptr<Model>> open_bonn_model(const std::string& path, BonnInfo* info = nullptr);

// Writers. The model must be an `fmf` model (fmf_factors()): DFMF takes per-channel models
// (color=dfmf -> colour model 11, or a Bonn DFMF read back with its colour model); FMF takes
// color=rgb models (and Bonn FMFs, with dynamic range reduction when they had it).
// half: store U, SxV and S as IEEE half (what Bonn's writers emit); a value beyond the half range
// is an error naming the block (write float instead). `meta` defaults to a version-4 block with
// channel names R, G, B; rotations default to none.
Status write_bonn_dfmf(const Model& model, const std::string& path, bool half, const BonnMeta* meta = nullptr);
Status write_bonn_fmf(const Model& model, const std::string& path, bool half, const BonnMeta* meta = nullptr);

}  // namespace btfc
