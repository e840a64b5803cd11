// The tile-cache simulator: cache operations (add / swap / evict by P = w v and the cost of
// eq. 10), streaming accounting and the per-frame measurements; see tile_cache.h.
#include "formats/bsvtf/tile_cache.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "core/limits.h"
#include "core/metrics.h"

namespace btfc {

Result<TileCacheSim> TileCacheSim::make(const BsvtfReader& f) {
  TileCacheSim s;
  s.m_geo = f.geometry();
  const bsvtf::Geometry& g = s.m_geo;
  s.m_textures = f.textures(), s.m_per_texture = g.tiles_total();
  for (int l = 0, base = 0; l < g.levels; base += int(g.tiles_in_level(l)), ++l) s.m_level_base.push_back(size_t(base));
  const size_t n = s.tiles(), tf = g.tile_floats();
  // Every decoded tile is held (tile_cache.h "Memory"): checked before decoding any.
  BTFC_RETURN_IF_ERROR(check_memory(n * tf * sizeof(float), f.path() + ": tile cache of " + std::to_string(n) + " decoded tiles"));
  s.m_weight.resize(n), s.m_energy.resize(n), s.m_bytes.resize(n);
  for (size_t t = 0; t < s.m_textures; ++t) {
    BTFC_ASSIGN_OR_RETURN(auto levels, f.decode_texture(t));
    std::vector<float> all;
    all.reserve(s.m_per_texture * tf);
    for (int l = 0; l < g.levels; ++l) {
      all.insert(all.end(), levels[size_t(l)].begin(), levels[size_t(l)].end());
      for (int ty = 0; ty < g.tiles_y(l); ++ty)
        for (int tx = 0; tx < g.tiles_x(l); ++tx) {
          const size_t gid = t * s.m_per_texture + s.m_level_base[size_t(l)] + size_t(ty) * size_t(g.tiles_x(l)) + size_t(tx);
          const BsvtfEntry& e = f.entries()[bsvtf_tile_entry(g, s.m_textures, t, l, tx, ty)];
          s.m_weight[gid] = e.weight, s.m_bytes[gid] = e.stored;
          s.m_energy[gid] = float(bsvtf::tile_weight(g, &all[(gid - t * s.m_per_texture) * tf], nullptr));
        }
    }
    s.m_tiles.push_back(std::move(all));
    BTFC_ASSIGN_OR_RETURN(std::vector<float> packet, f.read_packet(t));
    s.m_packets.push_back(std::move(packet));
    s.m_packet_bytes.push_back(f.entries()[bsvtf_packet_entry(t)].stored);
    s.m_block.push_back(f.texture_block(t)), s.m_group.push_back(f.texture_group(t));
  }
  for (const BsvtfBlock& b : f.blocks()) s.m_block_rows.push_back(b.rows), s.m_block_components.push_back(b.components);
  s.m_dfmf = f.color_model() != 0, s.m_offset = f.luminance_offset(), s.m_channels = f.channels();
  s.m_lights = int(f.lights().size()), s.m_views = int(f.views().size());
  s.m_header_bytes = f.header_bytes();
  return s;
}

// One run's state; the member functions are the paper's operations.
struct CacheRunState {
  const TileCacheSim& sim;
  const bsvtf::Geometry& g;
  TileCacheOptions opt;
  size_t per;                          // tiles per texture
  std::vector<int> level, tx, ty;      // per spatial id
  std::vector<long> parent;            // spatial id of the parent, -1 at level 0
  std::vector<uint8_t> resident, received;
  std::vector<int> pinned;             // frame in which the tile was inserted
  std::vector<uint8_t> packet;         // per texture: streamed
  std::vector<uint32_t> votes, direct; // per spatial id: eq. 9, and pixels needing exactly this tile
  size_t n_resident = 0;
  uint64_t bytes = 0, frame_bytes = 0;
  int frame = 0;
  TileCacheFrame stats;
  std::vector<float> converged;  // measure()'s converged luminance image (0 where the ray misses)

  CacheRunState(const TileCacheSim& s, const TileCacheOptions& o) : sim(s), g(s.m_geo), opt(o), per(s.m_per_texture) {
    for (int l = 0; l < g.levels; ++l)
      for (int y = 0; y < g.tiles_y(l); ++y)
        for (int x = 0; x < g.tiles_x(l); ++x) {
          level.push_back(l), tx.push_back(x), ty.push_back(y);
          parent.push_back(l == 0 ? -1 : long(sid(l - 1, x / 2, y / 2)));
        }
    resident.assign(sim.tiles(), 0), received.assign(sim.tiles(), 0), pinned.assign(sim.tiles(), -1);
    packet.assign(sim.m_textures, 0);
  }
  size_t sid(int l, int x, int y) const { return sim.m_level_base[size_t(l)] + size_t(y) * size_t(g.tiles_x(l)) + size_t(x); }
  // The tile of level l under full-resolution texel position (s, t) (eq. 2).
  size_t sid_at(int l, float s, float t) const {
    const double scale = std::ldexp(1.0, l - g.finest());
    const int x = std::min(int(s * scale) / g.tile, g.tiles_x(l) - 1), y = std::min(int(t * scale) / g.tile, g.tiles_y(l) - 1);
    return sid(l, x, y);
  }
  bool children_all_resident(size_t t, size_t s) const {
    const int l = level[s];
    if (l == g.finest()) return false;
    for (int y = 2 * ty[s]; y <= std::min(2 * ty[s] + 1, g.tiles_y(l + 1) - 1); ++y)
      for (int x = 2 * tx[s]; x <= std::min(2 * tx[s] + 1, g.tiles_x(l + 1) - 1); ++x)
        if (!resident[t * per + sid(l + 1, x, y)]) return false;
    return true;
  }
  bool afford(uint64_t cost) const { return opt.bandwidth == 0 || frame_bytes == 0 || frame_bytes + cost <= opt.bandwidth; }
  void send(uint64_t n) { bytes += n, frame_bytes += n; }
  void fetch(size_t gid) {
    if (!received[gid]) send(sim.m_bytes[gid]), received[gid] = 1;
  }
  // Inserts a tile; a parent now covered by all its children is removed (section 5.1).
  void insert(size_t gid) {
    fetch(gid);
    resident[gid] = 1, pinned[gid] = frame, ++n_resident;
    const size_t t = gid / per;
    const long p = parent[gid % per];
    if (p >= 0 && resident[t * per + size_t(p)] && direct[size_t(p)] == 0 && children_all_resident(t, size_t(p)))
      resident[t * per + size_t(p)] = 0, --n_resident, ++stats.covered;
  }
  void remove(size_t gid) { resident[gid] = 0, --n_resident; }

  void feedback(const std::vector<FeedbackPixel>& fb) {
    votes.assign(per, 0), direct.assign(per, 0);
    for (const FeedbackPixel& p : fb) {
      if (!p.hit) continue;
      for (int l = 0; l <= p.level; ++l) ++votes[sid_at(l, p.s, p.t)];
      ++direct[sid_at(p.level, p.s, p.t)];
    }
  }

  // The highest-priority add: P = w v (section 5.2); returns P (0: none).
  double best_add(size_t& best) const {
    double P = 0;
    for (size_t gid = 0; gid < sim.tiles(); ++gid) {
      const size_t t = gid / per, s = gid % per;
      if (resident[gid] || votes[s] == 0 || (parent[s] >= 0 && !resident[t * per + size_t(parent[s])])) continue;
      if (direct[s] == 0 && children_all_resident(t, s)) continue;  // would not show
      const double p = double(sim.m_weight[gid]) * votes[s];
      if (p > P) P = p, best = gid;
    }
    return P;
  }
  // Section 6: a texture's packet matters as much as its resident tiles' votes x energy.
  double best_packet(size_t& best) const {
    double P = 0;
    for (size_t t = 0; t < sim.m_textures; ++t) {
      if (packet[t]) continue;
      double p = 0;
      for (size_t s = 0; s < per; ++s)
        if (resident[t * per + s]) p += double(votes[s]) * sim.m_energy[t * per + s];
      if (p > P) P = p, best = t;
    }
    return P;
  }

  // The cheapest way to free one slot without touching `keep` (the best add's parent) or tiles
  // inserted this frame: an eviction (d2 < 0) or a swap of d1, d2 for their ancestor a.
  struct FreeOp {
    double cost = std::numeric_limits<double>::infinity();
    long d1 = -1, d2 = -1, a = -1;
  };
  FreeOp cheapest_free(size_t keep, size_t add) const {
    FreeOp best;
    struct Pair {
      double c1 = std::numeric_limits<double>::infinity(), c2 = c1;
      long d1 = -1, d2 = -1;
    };
    std::vector<Pair> anc(sim.tiles());
    for (size_t d = 0; d < sim.tiles(); ++d) {
      if (!resident[d] || pinned[d] == frame || d == keep || parent[d % per] < 0) continue;
      const size_t t = d / per;
      const double v = votes[d % per];
      double cost = 0;
      for (size_t cur = d % per; parent[cur] >= 0; cur = size_t(parent[cur])) {
        cost += double(sim.m_weight[t * per + cur]) * v;  // eq. 10: the level given up
        const size_t a = t * per + size_t(parent[cur]);
        if (resident[a]) {
          if (cost < best.cost) best = {cost, long(d), -1, -1};
          break;
        }
        Pair& p = anc[a];
        if (cost < p.c1) p.c2 = p.c1, p.d2 = p.d1, p.c1 = cost, p.d1 = long(d);
        else if (cost < p.c2) p.c2 = cost, p.d2 = long(d);
      }
    }
    for (size_t a = 0; a < anc.size(); ++a)
      if (anc[a].d2 >= 0 && a != add && anc[a].c1 + anc[a].c2 < best.cost) best = {anc[a].c1 + anc[a].c2, anc[a].d1, anc[a].d2, long(a)};
    return best;
  }

  void operate() {
    bool budget_left = true;
    // Every iteration inserts a tile that stays for the frame, so this bound is never reached
    // in practice; it only guarantees termination.
    for (size_t iter = 0; iter < 4 * sim.tiles() + 16; ++iter) {
      size_t add = 0, pk = 0;
      const double P = best_add(add), Q = best_packet(pk);
      if (Q > 0 && Q >= P) {
        if (!(budget_left = afford(sim.m_packet_bytes[pk]))) break;
        send(sim.m_packet_bytes[pk]), packet[pk] = 1, ++stats.packets;
        continue;
      }
      if (P <= 0) break;
      const uint64_t add_cost = received[add] ? 0 : sim.m_bytes[add];
      if (n_resident < opt.cache_tiles) {
        if (!(budget_left = afford(add_cost))) break;
        insert(add), ++stats.adds;
        continue;
      }
      const long p = parent[add % per];
      const size_t keep = p >= 0 ? (add / per) * per + size_t(p) : sim.tiles();
      const FreeOp op = cheapest_free(keep, add);
      if (!(op.cost < P)) break;
      const uint64_t a_cost = op.a >= 0 && !received[size_t(op.a)] ? sim.m_bytes[size_t(op.a)] : 0;
      if (!(budget_left = afford(add_cost + a_cost))) break;
      remove(size_t(op.d1));
      if (op.d2 >= 0) {
        remove(size_t(op.d2)), insert(size_t(op.a)), ++stats.swaps;
      } else {
        ++stats.evictions;
      }
      insert(add), ++stats.adds;
    }
    // The cache is settled: packets of textures with resident tiles still go out (a full cache
    // keeps some add's P above every packet's priority, which must not starve them).
    size_t pk = 0;
    while (budget_left && best_packet(pk) > 0 && (budget_left = afford(sim.m_packet_bytes[pk])))
      send(sim.m_packet_bytes[pk]), packet[pk] = 1, ++stats.packets;
  }

  // Bilinear lookup of texture t at level l, full-resolution position (s, t): K values.
  void sample(size_t t, int l, float s, float tt, float* out) const {
    const double scale = std::ldexp(1.0, l - g.finest());
    const size_t S = sid_at(l, s, tt), tf = g.tile_floats();
    const float* tile = &sim.m_tiles[t][S * tf];
    const int d = g.dim();
    const double px = s * scale - 0.5 - (g.tile * tx[S] - g.border), py = tt * scale - 0.5 - (g.tile * ty[S] - g.border);
    const int x0 = std::clamp(int(std::floor(px)), 0, d - 2), y0 = std::clamp(int(std::floor(py)), 0, d - 2);
    const float fx = float(std::clamp(px - x0, 0.0, 1.0)), fy = float(std::clamp(py - y0, 0.0, 1.0));
    for (int k = 0; k < g.comps; ++k) {
      const float* r0 = tile + (size_t(k) * d + size_t(y0)) * d + size_t(x0);
      const float* r1 = r0 + d;
      out[k] = (1 - fy) * ((1 - fx) * r0[0] + fx * r0[1]) + fy * ((1 - fx) * r1[0] + fx * r1[1]);
    }
  }

  // The level the renderer shows at a pixel: the needed level if resident, else the finest
  // resident coarser one, else (only finer ones resident) the nearest finer one; -1: none.
  int shown_level(size_t t, const FeedbackPixel& p) const {
    for (int l = p.level; l >= 0; --l)
      if (resident[t * per + sid_at(l, p.s, p.t)]) return l;
    for (int l = p.level + 1; l <= g.finest(); ++l)
      if (resident[t * per + sid_at(l, p.s, p.t)]) return l;
    return -1;
  }

  // Renders the converged and the cached image; sets stats.error and stats.ssim.
  void measure(const std::vector<FeedbackPixel>& fb) {
    const int W = opt.path.width, H = opt.path.height, K = g.comps, C = sim.m_channels;
    const int light = opt.light >= 0 ? opt.light : sim.m_lights / 2, view = opt.view >= 0 ? opt.view : 0;
    // Shading coefficients per texture: coef[t][channel or block value][k].
    std::vector<float> coef(sim.m_textures * size_t(C) * size_t(K), 0.0f);
    for (size_t t = 0; t < sim.m_textures; ++t)
      for (int c = 0; c < C; ++c) {
        if (sim.m_dfmf && c != sim.m_block[t]) continue;
        const size_t row = sim.m_dfmf ? size_t(light + sim.m_lights * view) : size_t(c + C * (light + sim.m_lights * view));
        for (int k = 0; k < K; ++k) coef[(t * size_t(C) + size_t(c)) * size_t(K) + size_t(k)] = sim.m_packets[t][row * size_t(K) + size_t(k)];
      }
    std::vector<float> lum_ref(fb.size(), 0.0f), lum_res(fb.size(), 0.0f);
    double E = 0, R = 0;
    std::vector<float> ref(static_cast<size_t>(K)), res(static_cast<size_t>(K));
    for (size_t i = 0; i < fb.size(); ++i) {
      const FeedbackPixel& p = fb[i];
      if (!p.hit) continue;
      float out_ref[3] = {0, 0, 0}, out_res[3] = {0, 0, 0};
      for (size_t t = 0; t < sim.m_textures; ++t) {
        sample(t, p.level, p.s, p.t, ref.data());
        const int l = shown_level(t, p);
        if (l >= 0) sample(t, l, p.s, p.t, res.data());
        else std::fill(res.begin(), res.end(), 0.0f);
        for (int k = 0; k < K; ++k) E += double(ref[size_t(k)] - res[size_t(k)]) * (ref[size_t(k)] - res[size_t(k)]), R += double(ref[size_t(k)]) * ref[size_t(k)];
        for (int c = 0; c < C; ++c)
          for (int k = 0; k < K; ++k) {
            const float u = coef[(t * size_t(C) + size_t(c)) * size_t(K) + size_t(k)];
            out_ref[c < 3 ? c : 2] += u * ref[size_t(k)];
            if (packet[t]) out_res[c < 3 ? c : 2] += u * res[size_t(k)];
          }
      }
      lum_ref[i] = luminance(out_ref), lum_res[i] = luminance(out_res);
    }
    stats.error = R > 0 ? std::sqrt(E / R) : std::sqrt(E);
    const float peak = *std::max_element(lum_ref.begin(), lum_ref.end());
    stats.ssim = ssim_gray(lum_ref.data(), lum_res.data(), W, H, peak > 0 ? peak : 1.0);
    converged = std::move(lum_ref);
  }
  // Luminance of a shaded value: colour model 11 and 13 values are Y' U' V' (bsvtf.h).
  float luminance(float* v) const {
    if (sim.m_dfmf) {
      const float e = sim.m_offset, y = std::exp(v[0]) - e, u = v[1] * (y + e), w = v[2] * (y + e);
      const float r = y + 1.13983f * w, gg = y - 0.39465f * u - 0.5806f * w, b = y + 2.03211f * u;
      v[0] = r, v[1] = gg, v[2] = b;
    }
    return sim.m_channels == 1 ? v[0] : 0.2126f * v[0] + 0.7152f * v[1] + 0.0722f * v[2];
  }
};

namespace {
Status check_shading(const TileCacheOptions& o, int lights, int views) {
  if (o.light >= lights || o.view >= views)
    return invalid_argument("tile cache: shading light " + std::to_string(o.light) + " / view " + std::to_string(o.view) + " outside the file's " +
                            std::to_string(lights) + " lights x " + std::to_string(views) + " views");
  return {};
}
}  // namespace

Result<std::vector<float>> TileCacheSim::converged_luminance(const TileCacheOptions& o, int frame) const {
  BTFC_RETURN_IF_ERROR(check_shading(o, m_lights, m_views));
  BTFC_ASSIGN_OR_RETURN(std::vector<FeedbackPixel> fb, feedback_image(m_geo, o.path, frame));
  CacheRunState st(*this, o);  // nothing resident: measure()'s reference side is all this needs
  st.measure(fb);
  std::vector<float> img = std::move(st.converged);
  for (size_t i = 0; i < fb.size(); ++i)
    if (!fb[i].hit) img[i] = std::numeric_limits<float>::quiet_NaN();
  return img;
}

Result<TileCacheRun> TileCacheSim::run(const TileCacheOptions& o) const {
  if (o.cache_tiles < 1) return invalid_argument("tile cache: at least one tile slot is needed");
  BTFC_RETURN_IF_ERROR(check_shading(o, m_lights, m_views));
  CacheRunState st(*this, o);
  st.send(m_header_bytes);
  TileCacheRun run;
  for (int f = 0; f < o.path.frames; ++f) {
    BTFC_ASSIGN_OR_RETURN(std::vector<FeedbackPixel> fb, feedback_image(m_geo, o.path, f));
    st.frame = f, st.frame_bytes = 0;
    st.stats = TileCacheFrame{};
    st.stats.frame = f;
    st.feedback(fb);
    st.operate();
    st.measure(fb);
    st.stats.resident = st.n_resident, st.stats.bytes = st.bytes;
    st.stats.working_set = m_textures * size_t(std::count_if(st.direct.begin(), st.direct.end(), [](uint32_t v) { return v > 0; }));
    run.frames.push_back(st.stats);
    run.mean_error += st.stats.error / o.path.frames, run.mean_ssim += st.stats.ssim / o.path.frames;
  }
  run.bytes = st.bytes;
  return run;
}

}  // namespace btfc
