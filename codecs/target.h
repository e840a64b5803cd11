// Budget targeting: pick a codec's quality knob so the model meets a target PSNR, a target mean
// SSIM, or a byte budget ("fit a budget", spec README section 1.4): the bytes of the model's .btfc
// file (model_file_bytes, codec.h: payload, headers, directions, statistics), what a user's `ls`
// shows; other model formats (a Bonn .btf) are not what the budget counts.
//
// Each codec marks one parameter as its quality knob (ParamSpec::quality_knob: larger = more
// accurate and more bytes; fmf rank, lpyr y, lpca components, ...). The search encodes, decodes
// and measures at probe settings: first the default (or the value the spec gives), then doubling
// or halving until the target is bracketed, then bisection, over the knob's integer range (a real
// knob is searched on a grid of 64 steps over its range). A byte budget interpolates instead of
// bisecting (bytes grow about linearly with the knob), probes no knob above the codec's
// budget_knob_limit for the data (or the spec's own value), and is refused for codecs that say
// why they cannot be searched (Codec::no_budget_search). Contract, for a knob along which the
// measure is monotone: the chosen setting meets the target and the next cheaper one (knob - 1
// step) does not, or it is the knob's cheapest setting. A target that even the most accurate
// setting misses (or a budget the cheapest one exceeds) is an error that reports the best reached.
// The other parameters of the spec are kept as given. A byte budget for a codec with
// budget_variants() (fmf: precision half and q at several bit depths) runs that search per
// variant and keeps the fitting model of the highest PSNR; keys the spec sets are not varied.
#pragma once
#include <memory>
#include <string>
#include <vector>

#include "codecs/codec.h"

namespace btfc {

struct Target {
  enum class Kind { psnr, ssim, max_bytes } kind = Kind::psnr;
  double value = 0;  // dB, mean SSIM in (0, 1], or bytes of the model's .btfc file (model_file_bytes)
};

struct TargetProbe {
  double knob = 0;
  double measure = 0;  // PSNR, mean SSIM or file bytes
  bool meets = false;
};

struct TargetChoice {
  std::string knob;                // parameter name
  double knob_value = 0;
  std::string spec;                // canonical spec of the chosen model
  double measure = 0;              // what it reached
  std::vector<TargetProbe> probes;  // in the order tried
  std::unique_ptr<Model> model;
  // A byte budget over Codec::budget_variants(): the chosen model's PSNR, and every setting's
  // best fit with its PSNR ("spec: 41.2 dB; ..."). A quality target reached through
  // Codec::quality_variants(): which setting reached it (" the knob alone missed it; ...").
  double psnr = 0;
  std::string variants;
  // A byte budget: the largest knob the search could probe (Codec::budget_knob_limit, or the
  // spec's own value when larger); 0 when the knob's whole range was open.
  double knob_limit = 0;
};

// The codec's quality knob, or nullptr when it declares none.
const ParamSpec* quality_knob(const Codec& codec);

Result<TargetChoice> choose_for_target(const Btf& btf, const std::string& spec, const Target& target, Context& ctx);

}  // namespace btfc
