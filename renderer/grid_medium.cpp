#include "renderer/grid_medium.h"

#include <algorithm>
#include <cmath>
#include <mutex>

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

class GridMedium final : public Medium {
 public:
  GridMedium(openvdb::FloatGrid::ConstPtr grid, float max_density, const GridMediumDesc& desc)
      : grid_(std::move(grid)),
        sigma_a_(desc.sigma_a),
        sigma_s_(desc.sigma_s),
        g_(desc.g),
        density_scale_(desc.density_scale),
        translate_(desc.translate),
        scale_(desc.scale) {
    // The majorant: the largest extinction of any channel anywhere. Trilinear interpolation never exceeds the
    // largest value it reads, so no point of the grid has a larger one.
    majorant_ = max_density * density_scale_ * max_component(sigma_a_ + sigma_s_);
    find_bounds();
  }

  bool scatters() const override { return majorant_ > 0 && (sigma_s_.x > 0 || sigma_s_.y > 0 || sigma_s_.z > 0); }
  HenyeyGreenstein phase() const override { return HenyeyGreenstein(g_); }
  bool homogeneous() const override { return false; }

  // Ratio tracking (Cramer 1978; Novák, Selle and Jarosz 2014, "Residual ratio tracking for estimating attenuation
  // in participating media", §3): tentative collisions at the majorant's rate, each multiplying the estimate by the
  // probability of a null collision there, 1 - sigma_t(x) / majorant, per channel. Once the estimate is small the
  // walk is ended by Russian roulette, unbiased (PBR 4th ed. §14.2.2).
  Rgb transmittance(const Ray& ray, float distance, MediumRng& rng) const override {
    Segment s;
    if (!clip(ray, distance, &s)) return Rgb(1);
    const Accessor acc = grid_->getConstUnsafeAccessor();
    const Rgb sigma_t = sigma_a_ + sigma_s_;
    Rgb tr(1);
    for (float t = s.t0;;) {
      t -= std::log1p(-rng.next()) / majorant_;
      if (!(t < s.t1)) return tr;
      const float d = density(s.o + s.d * t, acc);
      for (int c = 0; c < 3; ++c) tr[c] *= std::max(0.0f, 1 - sigma_t[c] * d / majorant_);
      if (max_component(tr) < 0.05f) {
        constexpr float q = 0.75f;  // the probability of ending the walk
        if (rng.next() < q) return Rgb(0);
        tr /= 1 - q;
      }
    }
  }

  // Delta tracking with chromatic coefficients: spectral tracking (Kutz, Habel, Li and Novák 2017, "Spectral and
  // decomposition tracking for rendering heterogeneous volumes", §3.2, its history-aware probabilities; Novák et al.
  // 2018, §5.1). Tentative collisions come at the rate of one grey majorant, the largest channel's; at each the
  // path scatters or goes on (a null collision) with probabilities proportional to the path's weight times
  // sigma_s(x) and times sigma_n(x) = majorant - sigma_t(x), averaged over the channels, and the weight takes the
  // chosen event's coefficient over majorant times its probability, per channel. Absorption is not sampled: it is
  // the part of the majorant neither event takes, and the estimate (no emission) is unbiased without it. The first
  // distance is drawn from `u`, the rest from `rng`.
  FreeFlight sample_free_flight(const Ray& ray, float t_max, const Rgb& throughput, float u,
                                MediumRng& rng) const override {
    Segment s;
    if (!clip(ray, t_max, &s)) return FreeFlight{false, t_max, Rgb(1)};
    const Accessor acc = grid_->getConstUnsafeAccessor();
    Rgb weight(1);
    float u_dist = u;
    for (float t = s.t0;;) {
      t -= std::log1p(-std::min(u_dist, 0x1.fffffep-1f)) / majorant_;
      if (!(t < s.t1)) return FreeFlight{false, t_max, weight};
      const float d = density(s.o + s.d * t, acc);
      const Rgb ss = sigma_s_ * d;
      Rgb sn;
      for (int c = 0; c < 3; ++c) sn[c] = std::max(0.0f, majorant_ - (sigma_a_[c] + sigma_s_[c]) * d);
      const Rgb h = throughput * weight;
      const float cs = std::max(0.0f, h.x * ss.x + h.y * ss.y + h.z * ss.z);
      const float cn = std::max(0.0f, h.x * sn.x + h.y * sn.y + h.z * sn.z);
      if (!(cs + cn > 0) || !std::isfinite(cs + cn)) return FreeFlight{false, t_max, Rgb(0)};
      const float p_scatter = cs / (cs + cn);
      if (rng.next() < p_scatter) return FreeFlight{true, t, weight * ss / (majorant_ * p_scatter)};
      weight *= sn / (majorant_ * (1 - p_scatter));
      u_dist = rng.next();
    }
  }

 private:
  // The density at scene point p: the grid's value there by trilinear interpolation (OpenVDB's BoxSampler), scaled.
  float density(const Vec3& p, const Accessor& acc) const {
    const Vec3 w = (p - translate_) / scale_;
    const openvdb::Vec3d index = grid_->transform().worldToIndex(openvdb::Vec3d(w.x, w.y, w.z));
    return std::max(0.0f, openvdb::tools::BoxSampler::sample(acc, index)) * density_scale_;
  }

  // The scene-space box around the grid's active voxels, one voxel wider on each side (interpolation reaches that
  // far): the corners of the index-space box taken through the grid's transform and the placement.
  void find_bounds() {
    openvdb::CoordBBox box = grid_->evalActiveVoxelBoundingBox();
    lo_ = Vec3(kInfinity);
    hi_ = Vec3(-kInfinity);
    if (box.empty()) return;
    box.expand(1);
    for (int corner = 0; corner < 8; ++corner) {
      const openvdb::Vec3d index((corner & 1 ? box.max() : box.min()).x(), (corner & 2 ? box.max() : box.min()).y(),
                                 (corner & 4 ? box.max() : box.min()).z());
      const openvdb::Vec3d w = grid_->transform().indexToWorld(index);
      const Vec3 p =
          Vec3(static_cast<float>(w.x()), static_cast<float>(w.y()), static_cast<float>(w.z())) * scale_ + translate_;
      lo_ = vmin(lo_, p);
      hi_ = vmax(hi_, p);
    }
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
  float g_, density_scale_;
  Vec3 translate_;
  float scale_;
  float majorant_ = 0;
  Vec3 lo_, hi_;
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
  return std::make_shared<GridMedium>(grid, range.max(), desc);
}

}  // namespace tessera
