// btfc_viewer_crop IN OUT.btfc X Y W H: a texel rectangle of a BTF (any input btfc reads) as a
// raw container. The browser test (tests/viewer/browser_test.sh) compresses a crop of the
// textile so that all four codecs at their default specs stay within its time budget
// (mlvq alone takes 100 s on the whole 64 x 64 textile here); btfc itself has no crop command.
#include <algorithm>
#include <cstdio>
#include <cstdlib>

#include "formats/btf_io.h"
#include "formats/reader.h"

int main(int argc, char** argv) {
  using namespace btfc;
  if (argc != 7) {
    std::fprintf(stderr, "usage: %s IN OUT.btfc X Y W H\n", argv[0]);
    return 1;
  }
  const int x0 = std::atoi(argv[3]), y0 = std::atoi(argv[4]), w = std::atoi(argv[5]), h = std::atoi(argv[6]);
  auto in = open_input(argv[1]);
  if (!in.ok()) return std::fprintf(stderr, "error: %s\n", in.status().message().c_str()), 2;
  auto src = in.value()->read();
  if (!src.ok()) return std::fprintf(stderr, "error: %s\n", src.status().message().c_str()), 2;
  const BtfDesc& d = src->desc();
  if (x0 < 0 || y0 < 0 || w < 1 || h < 1 || x0 + w > d.width || y0 + h > d.height)
    return std::fprintf(stderr, "error: rectangle outside the %dx%d BTF\n", d.width, d.height), 1;
  BtfDesc cd = d;
  cd.width = w, cd.height = h;
  auto dst = Btf::create(cd);
  if (!dst.ok()) return std::fprintf(stderr, "error: %s\n", dst.status().message().c_str()), 2;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float* a = src->abrdf(size_t(x0 + x) + size_t(d.width) * size_t(y0 + y));
      std::copy(a, a + d.abrdf_size(), dst->abrdf(size_t(x) + size_t(w) * size_t(y)));
    }
  if (Status s = write_btf(dst.value(), argv[2]); !s.ok()) return std::fprintf(stderr, "error: %s\n", s.message().c_str()), 2;
  return 0;
}
