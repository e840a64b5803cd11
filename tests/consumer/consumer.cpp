// Uses the installed btfc library the way docs/API.md shows: open any input, compress with a spec
// string, save, load, decode a region and a direction subset, evaluate at arbitrary directions,
// compare, export. Prints one JSON line for tests/install_test.sh to check against the CLI.
//   btfc_consumer INPUT SPEC OUT_DIR
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>

#include "codecs/codec.h"
#include "codecs/gpu_export.h"
#include "core/metrics.h"
#include "formats/btf_io.h"
#include "formats/gpu/export.h"
#include "formats/image_file.h"
#include "formats/reader.h"

using namespace btfc;

static int fail(const Status& s) {
  std::fprintf(stderr, "btfc_consumer: %s\n", s.message().c_str());
  return 2;
}

int main(int argc, char** argv) {
  if (argc != 4) {
    std::fprintf(stderr, "usage: btfc_consumer INPUT SPEC OUT_DIR\n");
    return 1;
  }
  const std::string in = argv[1], spec = argv[2], dir = argv[3];
  auto input = open_input(in);  // image set, Bonn .btf or .btfc, probed once
  if (!input.ok()) return fail(input.status());
  auto btf = input.value()->read();
  if (!btf.ok()) return fail(btf.status());
  auto resolved = resolve_spec(spec);  // unknown parameters are errors
  if (!resolved.ok()) return fail(resolved.status());
  auto [codec, params] = resolved.value();
  Context ctx;
  auto model = codec->encode(btf.value(), params, ctx);
  if (!model.ok()) return fail(model.status());
  const std::string path = dir + "/consumer.btfc";
  if (Status s = write_model(*model.value(), path); !s.ok()) return fail(s);

  auto loaded = open_model(path);
  if (!loaded.ok()) return fail(loaded.status());
  const Model& m = *loaded.value();
  Btf full;
  if (Status s = m.decode_all(full); !s.ok()) return fail(s);
  DecodeRequest req;
  req.x0 = 1, req.y0 = 2, req.width = 3, req.height = 2;
  req.lights = {0, 4};
  Btf part;
  if (Status s = m.decode(req, part); !s.ok()) return fail(s);
  // The region decode equals the full decode at the same texels and directions.
  double region_diff = 0;
  for (int y = 0; y < 2; ++y)
    for (int x = 0; x < 3; ++x)
      for (size_t li = 0; li < 2; ++li)
        for (size_t v = 0; v < part.desc().num_views(); ++v)
          for (int c = 0; c < part.desc().channels; ++c) {
            const double d = double(part.at(x, y, li, v, c)) - double(full.at(x + 1, y + 2, req.lights[li], v, c));
            region_diff = std::max(region_diff, std::abs(d));
          }
  float value[4] = {};
  if (Status s = m.eval_dir(0, 0, dir_from_theta_phi(0.5, 0.7), dir_from_theta_phi(0.2, 1.9), value); !s.ok()) return fail(s);
  auto metrics = compare_btf(btf.value(), full);
  if (!metrics.ok()) return fail(metrics.status());
  auto bundle = gpu::build_export(m, gpu::ExportOptions{});
  if (!bundle.ok()) return fail(bundle.status());
  if (Status s = gpu::write_export_dir(bundle.value(), dir + "/gpu"); !s.ok()) return fail(s);
  // Which image plugin served an image-set input (the installed one: btfcConfig.cmake's path).
  const std::string plugin = image_file::loaded() ? image_file::plugin_path() : "";
  std::printf("{\"spec\": \"%s\", \"psnr\": %.17g, \"rmse\": %.17g, \"region_max_diff\": %.17g, \"eval\": [%.9g, %.9g, %.9g], \"imageio\": \"%s\"}\n",
              m.spec().c_str(), metrics->psnr, metrics->rmse, region_diff, value[0], value[1], value[2], plugin.c_str());
  return 0;
}
