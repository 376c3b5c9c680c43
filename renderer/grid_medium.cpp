#include "renderer/grid_medium.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <mutex>
#include <vector>

#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/Count.h>
#include <openvdb/tools/Interpolation.h>

namespace tessera {

namespace {

using Accessor = openvdb::FloatGrid::ConstUnsafeAccessor;

// The part of a ray that crosses the grid's bounds: positions o + d t for t in [t0, t1], d of unit length.
struct Segment {
  Vec3 o, d;
  float t0 = 0, t1 = 0;
};

// A stretch [t0, t1) of a ray over which `sigma` bounds the extinction of every channel.
struct MajorantSegment {
  float t0 = 0, t1 = 0, sigma = 0;
};

// A coarse grid of majorants over the medium's bounds (PBR 4th ed. §11.4.3, majorant grids): each cell holds the
// largest extinction any point of it can have. Delta and ratio tracking then take tentative collisions at each
// cell's own rate, few where the medium is thin and none where it is empty, rather than everywhere at the rate of
// the densest point (Novák et al. 2018, §5.1, piecewise-constant majorants).
struct MajorantGrid {
  Vec3 lo, hi;
  int res[3] = {1, 1, 1};
  std::vector<float> sigma;  // x fastest
  float at(int x, int y, int z) const { return sigma[(static_cast<size_t>(z) * res[1] + y) * res[0] + x]; }
};

// The segments of a ray's stretch in the bounds, cell by cell along a 3D DDA (Amanatides and Woo 1987, "A fast voxel
// traversal algorithm for ray tracing"; PBR 4th ed. §11.4.3, DDAMajorantIterator); with no grid, the one segment of
// the whole stretch at the global majorant.
class MajorantWalk {
 public:
  MajorantWalk(const MajorantGrid* grid, float global, const Segment& s)
      : grid_(grid), global_(global), t_(s.t0), t1_(s.t1) {
    if (!grid_) return;
    const Vec3 extent = grid_->hi - grid_->lo;
    const Vec3 p = s.o + s.d * s.t0;
    for (int a = 0; a < 3; ++a) {
      const float cell_size = extent[a] / grid_->res[a];
      cell_[a] = std::clamp(static_cast<int>((p[a] - grid_->lo[a]) / cell_size), 0, grid_->res[a] - 1);
      if (s.d[a] == 0) {
        next_[a] = kInfinity;
        delta_[a] = kInfinity;
        step_[a] = 0;
      } else if (s.d[a] > 0) {
        next_[a] = s.t0 + (grid_->lo[a] + (cell_[a] + 1) * cell_size - p[a]) / s.d[a];
        delta_[a] = cell_size / s.d[a];
        step_[a] = 1;
      } else {
        next_[a] = s.t0 + (grid_->lo[a] + cell_[a] * cell_size - p[a]) / s.d[a];
        delta_[a] = -cell_size / s.d[a];
        step_[a] = -1;
      }
    }
  }

  // The next segment; false once the stretch is done.
  bool next(MajorantSegment* seg) {
    if (!(t_ < t1_)) return false;
    if (!grid_) {
      *seg = {t_, t1_, global_};
      t_ = t1_;
      return true;
    }
    const int axis = next_[0] < next_[1] ? (next_[0] < next_[2] ? 0 : 2) : (next_[1] < next_[2] ? 1 : 2);
    const float end = std::max(t_, std::min(next_[axis], t1_));  // never back, whatever the rounding
    *seg = {t_, end, grid_->at(cell_[0], cell_[1], cell_[2])};
    t_ = end;
    cell_[axis] += step_[axis];
    if (cell_[axis] < 0 || cell_[axis] >= grid_->res[axis]) t_ = t1_;
    next_[axis] += delta_[axis];
    return true;
  }

 private:
  const MajorantGrid* grid_;
  float global_, t_, t1_;
  int cell_[3] = {0, 0, 0}, step_[3] = {0, 0, 0};
  float next_[3] = {0, 0, 0}, delta_[3] = {0, 0, 0};
};

class GridMedium final : public Medium {
 public:
  GridMedium(openvdb::FloatGrid::ConstPtr grid, float max_density, const GridMediumDesc& desc)
      : grid_(std::move(grid)),
        sigma_a_(desc.sigma_a),
        sigma_s_(desc.sigma_s),
        unit_(desc.sigma_a, desc.sigma_s, desc.g),
        g_(desc.g),
        density_scale_(desc.density_scale),
        translate_(desc.translate),
        scale_(desc.scale) {
    // The global majorant: the largest extinction of any channel anywhere. Trilinear interpolation never exceeds
    // the largest value it reads, so no point of the grid has a larger one.
    majorant_ = max_density * density_scale_ * max_component(sigma_a_ + sigma_s_);
    find_bounds();
    if (desc.majorant_grid && lo_.x <= hi_.x) build_majorant_grid();
  }

  // The largest extinction anywhere, per scene unit, and the optical depth at it across the bounds' diagonal.
  float majorant() const { return majorant_; }
  double majorant_optical_depth() const {
    return lo_.x <= hi_.x ? static_cast<double>(majorant_) * length(hi_ - lo_) : 0.0;
  }

  bool scatters() const override { return majorant_ > 0 && (sigma_s_.x > 0 || sigma_s_.y > 0 || sigma_s_.z > 0); }
  HenyeyGreenstein phase() const override { return HenyeyGreenstein(g_); }
  bool homogeneous() const override { return false; }

  // Ratio tracking (Cramer 1978; Novák, Selle and Jarosz 2014, "Residual ratio tracking for estimating attenuation
  // in participating media", §3): tentative collisions at the majorant's rate, each multiplying the estimate by the
  // probability of a null collision there, 1 - sigma_t(x) / majorant, per channel. Once the estimate is small the
  // walk is ended by Russian roulette, unbiased (PBR 4th ed. §14.2.2). Past kMaxTentativeCollisions the rest of the
  // stretch is ray-marched.
  Rgb transmittance(const Ray& ray, float distance, MediumRng& rng) const override {
    Segment s;
    if (!clip(ray, distance, &s)) return Rgb(1);
    const Accessor acc = grid_->getConstUnsafeAccessor();
    const Rgb sigma_t = sigma_a_ + sigma_s_;
    Rgb tr(1);
    int collisions = 0;
    MajorantWalk walk(majorants_.get(), majorant_, s);
    for (MajorantSegment seg; walk.next(&seg);) {
      if (!(seg.sigma > 0)) continue;
      for (float t = seg.t0;;) {
        t -= std::log1p(-rng.next()) / seg.sigma;
        if (!(t < seg.t1)) break;
        if (++collisions > kMaxTentativeCollisions)
          return tr * unit_.transmittance(march(s, t, acc, rng.next()).integral());
        const float d = density(s.o + s.d * t, acc);
        for (int c = 0; c < 3; ++c) tr[c] *= std::max(0.0f, 1 - sigma_t[c] * d / seg.sigma);
        if (max_component(tr) < 0.05f) {
          constexpr float q = 0.75f;  // the probability of ending the walk
          if (rng.next() < q) return Rgb(0);
          tr /= 1 - q;
        }
      }
    }
    return tr;
  }

  // Delta tracking with chromatic coefficients: spectral tracking (Kutz, Habel, Li and Novák 2017, "Spectral and
  // decomposition tracking for rendering heterogeneous volumes", §3.2, its history-aware probabilities; Novák et al.
  // 2018, §5.1). Tentative collisions come at the rate of one grey majorant, the largest channel's; at each the
  // path scatters or goes on (a null collision) with probabilities proportional to the path's weight times
  // sigma_s(x) and times sigma_n(x) = majorant - sigma_t(x), summed over the channels, and the weight takes the
  // chosen event's coefficient over majorant times its probability, per channel. Absorption is not sampled: it is
  // the part of the majorant neither event takes, and the estimate (no emission) is unbiased without it. The first
  // distance is drawn from `u`, the rest from `rng`. Past kMaxTentativeCollisions the flight through the rest of
  // the stretch is sampled in the ray-marched medium.
  FreeFlight sample_free_flight(const Ray& ray, float t_max, const Rgb& throughput, float u,
                                MediumRng& rng) const override {
    Segment s;
    if (!clip(ray, t_max, &s)) return FreeFlight{false, t_max, Rgb(1)};
    const Accessor acc = grid_->getConstUnsafeAccessor();
    Rgb weight(1);
    float u_dist = u;
    int collisions = 0;
    MajorantWalk walk(majorants_.get(), majorant_, s);
    for (MajorantSegment seg; walk.next(&seg);) {
      if (!(seg.sigma > 0)) continue;
      for (float t = seg.t0;;) {
        t -= std::log1p(-std::min(u_dist, 0x1.fffffep-1f)) / seg.sigma;
        u_dist = rng.next();
        if (!(t < seg.t1)) break;
        if (++collisions > kMaxTentativeCollisions)
          return marched_free_flight(march(s, t, acc, u_dist), t_max, throughput * weight, rng.next(), weight);
        const float d = density(s.o + s.d * t, acc);
        const Rgb ss = sigma_s_ * d;
        Rgb sn;
        for (int c = 0; c < 3; ++c) sn[c] = std::max(0.0f, seg.sigma - (sigma_a_[c] + sigma_s_[c]) * d);
        const Rgb h = throughput * weight;
        const float cs = std::max(0.0f, h.x * ss.x + h.y * ss.y + h.z * ss.z);
        const float cn = std::max(0.0f, h.x * sn.x + h.y * sn.y + h.z * sn.z);
        if (!(cs + cn > 0) || !std::isfinite(cs + cn)) return FreeFlight{false, t_max, Rgb(0)};
        const float p_scatter = cs / (cs + cn);
        if (u_dist < p_scatter) return FreeFlight{true, t, weight * ss / (seg.sigma * p_scatter)};
        weight *= sn / (seg.sigma * (1 - p_scatter));
        u_dist = rng.next();
      }
    }
    return FreeFlight{false, t_max, weight};
  }

 private:
  // The rest of a stretch from t by ray marching (Perlin and Hoffert 1989, "Hypertexture"): kMarchPoints equal
  // intervals, each of the density at its point offset by `u` in [0, 1) (a jittered midpoint rule), for the rest of
  // a tracking call that reached kMaxTentativeCollisions. A biased stand-in of bounded cost (the quadrature's
  // error), near the medium where the density varies little across an interval.
  struct MarchedRest {
    static constexpr int kMarchPoints = 64;
    float t0 = 0, dt = 0;
    std::array<float, kMarchPoints> density{};
    // The integral of the density over the rest: the optical depth at unit extinction.
    float integral() const {
      double sum = 0;
      for (float d : density) sum += d;
      return static_cast<float>(sum * dt);
    }
    // The distance along the ray at which the integral from t0 reaches `depth` (<= integral()).
    float distance_at(float depth) const {
      float from = 0;
      for (int i = 0; i < kMarchPoints; ++i) {
        const float to = from + density[i] * dt;
        if (depth < to && density[i] > 0) return t0 + i * dt + (depth - from) / density[i];
        from = to;
      }
      return t0 + kMarchPoints * dt;
    }
  };
  MarchedRest march(const Segment& s, float t, const Accessor& acc, float u) const {
    MarchedRest rest;
    rest.t0 = t;
    rest.dt = std::max(0.0f, s.t1 - t) / MarchedRest::kMarchPoints;
    for (int i = 0; i < MarchedRest::kMarchPoints; ++i)
      rest.density[i] = density(s.o + s.d * (t + (i + u) * rest.dt), acc);
    return rest;
  }

  // A free flight through the marched rest, for a path of throughput `throughput` that carries `weight` so far. In
  // the coordinate D(t), the integral of the density from the rest's start, every channel's transmittance is
  // exp(-sigma_t D): the rest is the homogeneous medium of the grid's coefficients at density 1 over D's range, whose
  // flight (chromatic, by its one-sample MIS over the channels) is sampled from `u` and taken back to a distance.
  // The weight is the same in either coordinate: the density at the point divides both the integrand and the pdf.
  FreeFlight marched_free_flight(const MarchedRest& rest, float t_max, const Rgb& throughput, float u,
                                 const Rgb& weight) const {
    const FreeFlight f = unit_.sample_free_flight(rest.integral(), throughput, u);
    if (!f.scattered) return FreeFlight{false, t_max, weight * f.weight};
    // A scattering of weight 0 (no channel scatters) is an absorption, which tracking reports so.
    if (!(max_component(f.weight) > 0)) return FreeFlight{false, t_max, Rgb(0)};
    return FreeFlight{true, std::min(rest.distance_at(f.t), rest.t0 + MarchedRest::kMarchPoints * rest.dt),
                      weight * f.weight};
  }

  // The density at scene point p: the grid's value there by trilinear interpolation (OpenVDB's BoxSampler), scaled.
  float density(const Vec3& p, const Accessor& acc) const {
    const Vec3 w = (p - translate_) / scale_;
    const openvdb::Vec3d index = grid_->transform().worldToIndex(openvdb::Vec3d(w.x, w.y, w.z));
    return std::max(0.0f, openvdb::tools::BoxSampler::sample(acc, index)) * density_scale_;
  }

  // The scene-space box around index-space box `box` widened by one voxel on each side (interpolation reaches that
  // far): its corners taken through the grid's transform and the placement.
  void scene_box(openvdb::CoordBBox box, Vec3* lo, Vec3* hi) const {
    box.expand(1);
    *lo = Vec3(kInfinity);
    *hi = Vec3(-kInfinity);
    for (int corner = 0; corner < 8; ++corner) {
      const openvdb::Vec3d index((corner & 1 ? box.max() : box.min()).x(), (corner & 2 ? box.max() : box.min()).y(),
                                 (corner & 4 ? box.max() : box.min()).z());
      const openvdb::Vec3d w = grid_->transform().indexToWorld(index);
      const Vec3 p =
          Vec3(static_cast<float>(w.x()), static_cast<float>(w.y()), static_cast<float>(w.z())) * scale_ + translate_;
      *lo = vmin(*lo, p);
      *hi = vmax(*hi, p);
    }
  }

  // The medium's bounds: the scene-space box around the grid's active voxels.
  void find_bounds() {
    const openvdb::CoordBBox box = grid_->evalActiveVoxelBoundingBox();
    lo_ = Vec3(kInfinity);
    hi_ = Vec3(-kInfinity);
    if (!box.empty()) scene_box(box, &lo_, &hi_);
  }

  // The majorant grid over the bounds, of cells about 8 voxels wide (an OpenVDB leaf node's width), at most 64 a
  // side: each cell the largest extinction of the values whose interpolation reaches it, found a leaf node or tile
  // at a time (every value of a leaf, active or not, and each tile over its box), and of the background where no
  // node lies.
  void build_majorant_grid() {
    auto m = std::make_unique<MajorantGrid>();
    m->lo = lo_;
    m->hi = hi_;
    const Vec3 extent = hi_ - lo_;
    const float voxel = static_cast<float>(grid_->voxelSize()[0]) * scale_;
    for (int a = 0; a < 3; ++a) m->res[a] = std::clamp(static_cast<int>(std::ceil(extent[a] / (8 * voxel))), 1, 64);
    const float sigma_max = density_scale_ * max_component(sigma_a_ + sigma_s_);
    m->sigma.assign(static_cast<size_t>(m->res[0]) * m->res[1] * m->res[2],
                    std::max(0.0f, grid_->background()) * sigma_max);
    const auto add = [&](const openvdb::CoordBBox& box, float value) {
      Vec3 lo, hi;
      scene_box(box, &lo, &hi);
      int from[3], to[3];
      for (int a = 0; a < 3; ++a) {
        const float cell_size = extent[a] / m->res[a];
        from[a] = std::clamp(static_cast<int>(std::floor((lo[a] - m->lo[a]) / cell_size)), 0, m->res[a] - 1);
        to[a] = std::clamp(static_cast<int>(std::floor((hi[a] - m->lo[a]) / cell_size)), 0, m->res[a] - 1);
      }
      const float sigma = std::max(0.0f, value) * sigma_max;
      for (int z = from[2]; z <= to[2]; ++z)
        for (int y = from[1]; y <= to[1]; ++y)
          for (int x = from[0]; x <= to[0]; ++x) {
            float& cell = m->sigma[(static_cast<size_t>(z) * m->res[1] + y) * m->res[0] + x];
            cell = std::max(cell, sigma);
          }
    };
    for (auto leaf = grid_->tree().cbeginLeaf(); leaf; ++leaf) {
      float largest = -kInfinity;
      for (auto v = leaf->cbeginValueAll(); v; ++v) largest = std::max(largest, *v);
      add(leaf->getNodeBoundingBox(), largest);
    }
    for (auto tile = grid_->tree().cbeginValueAll(); tile; ++tile) {
      if (tile.isVoxelValue()) continue;
      openvdb::CoordBBox box;
      tile.getBoundingBox(box);
      add(box, *tile);
    }
    majorants_ = std::move(m);
  }

  // The part of the first `distance` scene units of `ray` inside the bounds (slab test, Kay and Kajiya 1986); false
  // when none, or when nothing there interacts.
  bool clip(const Ray& ray, float distance, Segment* s) const {
    if (!(majorant_ > 0)) return false;
    const float len = length(ray.dir);
    if (!(len > 0)) return false;
    s->o = ray.origin;
    s->d = ray.dir / len;
    s->t0 = 0;
    s->t1 = distance;
    for (int a = 0; a < 3; ++a) {
      const float inv = 1 / s->d[a];
      float n = (lo_[a] - s->o[a]) * inv, f = (hi_[a] - s->o[a]) * inv;
      if (n > f) std::swap(n, f);
      if (std::isnan(n) || std::isnan(f)) {  // parallel to the slab, on its plane
        if (s->o[a] < lo_[a] || s->o[a] > hi_[a]) return false;
        continue;
      }
      s->t0 = std::max(s->t0, n);
      s->t1 = std::min(s->t1, f);
    }
    return s->t0 < s->t1;
  }

  openvdb::FloatGrid::ConstPtr grid_;
  Rgb sigma_a_, sigma_s_;
  HomogeneousMedium unit_;  // the coefficients at density 1, as a medium: the marched rest's, per unit of density
  float g_, density_scale_;
  Vec3 translate_;
  float scale_;
  float majorant_ = 0;
  Vec3 lo_, hi_;
  std::unique_ptr<const MajorantGrid> majorants_;  // null: the global majorant throughout
};

// The name of the grid to read: the one asked for, else "density", else the file's first float grid.
std::string choose_grid(const openvdb::GridPtrVec& grids, const std::string& asked) {
  std::string names;
  for (const auto& g : grids) {
    if (!asked.empty() && g->getName() == asked) return asked;
    names += (names.empty() ? "\"" : ", \"") + g->getName() + "\"";
  }
  if (!asked.empty())
    throw GridError("grid_name", "the file has no grid \"" + asked.substr(0, 64) + "\" (it has " +
                                     (names.empty() ? "none" : names) + ")");
  for (const auto& g : grids)
    if (g->getName() == "density") return "density";
  for (const auto& g : grids)
    if (g->isType<openvdb::FloatGrid>()) return g->getName();
  throw GridError("grid", "the file holds no float grid (it has " + (names.empty() ? "none" : names) + ")");
}

// The largest and smallest value of a grid, active or not (interpolation reads inactive values too): OpenVDB's
// minMax over the active values, then the inactive ones and the background.
openvdb::math::MinMax<float> value_range(const openvdb::FloatGrid& grid) {
  openvdb::math::MinMax<float> range = openvdb::tools::minMax(grid.tree());
  range.add(grid.background());
  for (auto it = grid.cbeginValueOff(); it; ++it) range.add(*it);
  return range;
}

// Refuses a medium too dense to track (kMaxMajorantOpticalDepth), naming density_scale, the factor a scene most
// often sets past all measure.
void check_optical_depth(const GridMedium& medium, const std::string& name) {
  const double depth = medium.majorant_optical_depth();
  if (!(depth > kMaxMajorantOpticalDepth)) return;
  char text[320];
  std::snprintf(text, sizeof text,
                "the grid \"%s\" is too dense to render: its largest extinction (density_scale x its largest density x "
                "the largest of sigma_a + sigma_s) is %.3g per unit, an optical depth of %.3g across its %.3g units, "
                "more than the %.3g (2^24) a medium may have; lower density_scale",
                name.substr(0, 64).c_str(), medium.majorant(), depth, depth / medium.majorant(),
                kMaxMajorantOpticalDepth);
  throw GridError("density_scale", text);
}

}  // namespace

std::shared_ptr<const Medium> load_grid_medium(const GridMediumDesc& desc) {
  static std::once_flag initialized;
  std::call_once(initialized, [] { openvdb::initialize(); });
  openvdb::io::File file(desc.file.string());
  openvdb::GridPtrVecPtr headers;
  try {
    file.open(false);  // read into memory, not mapped: the file may be removed while a render runs
    headers = file.readAllGridMetadata();
  } catch (const std::exception& e) {
    throw GridError("grid", std::string("is not a readable OpenVDB file: ") + e.what());
  }
  const std::string name = choose_grid(*headers, desc.grid_name);
  openvdb::GridBase::ConstPtr header;
  for (const auto& g : *headers)
    if (g->getName() == name) header = g;
  if (!header->isType<openvdb::FloatGrid>())
    throw GridError(desc.grid_name.empty() ? "grid" : "grid_name",
                    "the grid \"" + name + "\" holds " + header->valueType() + " values, not float densities");
  // The voxel count the writer recorded, checked before the voxels are read; the count read is checked after.
  const auto too_many = [&](uint64_t voxels) {
    if (voxels > desc.max_voxels)
      throw GridError("grid", "the grid \"" + name + "\" has " + std::to_string(voxels) + " voxels, more than the " +
                                  std::to_string(desc.max_voxels) + " a medium may have");
  };
  if (auto count = header->getMetadata<openvdb::Int64Metadata>(openvdb::GridBase::META_FILE_VOXEL_COUNT))
    too_many(static_cast<uint64_t>(std::max<int64_t>(0, count->value())));
  openvdb::FloatGrid::Ptr grid;
  try {
    grid = openvdb::gridPtrCast<openvdb::FloatGrid>(file.readGrid(name));
  } catch (const std::exception& e) {
    throw GridError("grid", "the grid \"" + name + "\" cannot be read: " + e.what());
  }
  if (!grid) throw GridError("grid", "the grid \"" + name + "\" cannot be read");
  too_many(grid->activeVoxelCount());
  const openvdb::math::MinMax<float> range = value_range(*grid);
  if (!std::isfinite(range.min()) || !std::isfinite(range.max()))
    throw GridError("grid", "the grid \"" + name + "\" holds a density that is not a finite number");
  if (range.min() < 0)
    throw GridError("grid", "the grid \"" + name + "\" holds negative densities (down to " +
                                std::to_string(range.min()) + "); densities are at least 0");
  auto medium = std::make_shared<GridMedium>(grid, range.max(), desc);
  check_optical_depth(*medium, name);
  return medium;
}

}  // namespace tessera
