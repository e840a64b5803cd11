// Float RGB EXR images through OpenEXR (formats/exr/envmap.h).
#include "formats/exr/envmap.h"

#include <ImfChannelList.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfInputFile.h>
#include <ImfOutputFile.h>
#include <unistd.h>

#include <cstdio>
#include <exception>

namespace btfc {

Status write_rgb_exr(const std::string& path, int w, int h, const std::vector<float>& rgb) {
  if (w <= 0 || h <= 0 || rgb.size() != size_t(w) * size_t(h) * 3)
    return invalid_argument(path + ": image " + std::to_string(w) + "x" + std::to_string(h) + " does not match " + std::to_string(rgb.size()) + " values");
  const std::string tmp = path + ".tmp-" + std::to_string(::getpid());
  try {
    Imf::Header header(w, h);
    for (const char* ch : {"R", "G", "B"}) header.channels().insert(ch, Imf::Channel(Imf::FLOAT));
    Imf::OutputFile file(tmp.c_str(), header);
    Imf::FrameBuffer fb;
    char* base = reinterpret_cast<char*>(const_cast<float*>(rgb.data()));
    const size_t xs = 3 * sizeof(float), ys = xs * size_t(w);
    fb.insert("R", Imf::Slice(Imf::FLOAT, base, xs, ys));
    fb.insert("G", Imf::Slice(Imf::FLOAT, base + sizeof(float), xs, ys));
    fb.insert("B", Imf::Slice(Imf::FLOAT, base + 2 * sizeof(float), xs, ys));
    file.setFrameBuffer(fb);
    file.writePixels(h);
  } catch (const std::exception& e) {
    std::remove(tmp.c_str());
    return io_error(path + ": " + e.what());
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    std::remove(tmp.c_str());
    return io_error(path + ": cannot rename the temporary file into place");
  }
  return {};
}

Result<std::vector<float>> read_rgb_exr(const std::string& path, int& w, int& h) {
  try {
    Imf::InputFile file(path.c_str());
    const Imath::Box2i dw = file.header().dataWindow();
    const long long ww = (long long)dw.max.x - dw.min.x + 1, hh = (long long)dw.max.y - dw.min.y + 1;
    if (ww <= 0 || hh <= 0 || ww * hh > (1LL << 28)) return corrupt_data(path + ": bad EXR data window");
    const Imf::ChannelList& chans = file.header().channels();
    const bool rgb = chans.findChannel("R") && chans.findChannel("G") && chans.findChannel("B");
    if (!rgb && !chans.findChannel("Y")) return corrupt_data(path + ": EXR has neither R, G, B nor Y channels");
    w = int(ww), h = int(hh);
    std::vector<float> out(size_t(ww * hh) * 3, 0.f);
    const size_t xs = 3 * sizeof(float), ys = xs * size_t(ww);
    // OpenEXR addresses pixels by absolute coordinates: shift the base by the window origin.
    char* base = reinterpret_cast<char*>(out.data()) - (ptrdiff_t(dw.min.x) * ptrdiff_t(xs) + ptrdiff_t(dw.min.y) * ptrdiff_t(ys));
    Imf::FrameBuffer fb;
    if (rgb) {
      fb.insert("R", Imf::Slice(Imf::FLOAT, base, xs, ys));
      fb.insert("G", Imf::Slice(Imf::FLOAT, base + sizeof(float), xs, ys));
      fb.insert("B", Imf::Slice(Imf::FLOAT, base + 2 * sizeof(float), xs, ys));
    } else {
      fb.insert("Y", Imf::Slice(Imf::FLOAT, base, xs, ys));
    }
    file.setFrameBuffer(fb);
    file.readPixels(dw.min.y, dw.max.y);
    if (!rgb)
      for (size_t i = 0; i < out.size(); i += 3) out[i + 1] = out[i + 2] = out[i];
    return out;
  } catch (const std::exception& e) {
    return io_error(path + ": " + e.what());
  }
}

Result<EnvironmentSH> read_environment(const std::string& path, int order) {
  int w = 0, h = 0;
  BTFC_ASSIGN_OR_RETURN(std::vector<float> rgb, read_rgb_exr(path, w, h));
  auto env = project_latlong(rgb.data(), w, h, order);
  if (!env.ok()) return env.status().with_context(path);
  return env;
}

}  // namespace btfc
