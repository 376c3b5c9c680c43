// Light from infinitely far away: a constant radiance, or an equirectangular map (latitude-longitude, +y up)
// importance-sampled by a piecewise-constant 2D distribution over luminance x sin(theta).
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "renderer/math.h"
#include "renderer/sampling.h"

namespace tessera {

class EnvironmentMap {
 public:
  // `rgb` is width*height linear RGB, row 0 at the top (the +y pole).
  EnvironmentMap(int width, int height, std::vector<float> rgb);
  // Through OpenImageIO; throws on failure, and for maps of more than kMaxTexels texels (2 GB of cells).
  static std::shared_ptr<EnvironmentMap> load(const std::string& path);
  // What load() checks before it reads the pixels (the file opens as an image within the limits), from the header
  // alone; throws the same way.
  static void check(const std::string& path);
  static constexpr size_t kMaxTexels = size_t{16384} * 8192;
  // Radiance above this is clamped to it (the sun is about 1.6e9 W/(m^2 sr)): the sampling sums, stored as floats,
  // then stay finite for any map of the allowed size.
  static constexpr float kMaxRadiance = 1e20f;

  // Radiance towards the viewer from direction `dir` (a direction in map space) as it is seen (by the camera, or
  // through mirrors and glass): filtered bilinearly between texel centres.
  Rgb lookup(const Vec3& dir) const { return lookup_uv(direction_to_uv(dir)); }
  // The radiance the map lights surfaces with from `dir`: its texel's, constant over the texel as the density that
  // `sample` draws directions with is, so that importance sampling follows it exactly (and one texel is read, not
  // four: light sampling of a large map is bound by the memory reads). `pdf` receives that density.
  Rgb lighting(const Vec3& dir, float* pdf) const;
  // Samples a direction with density pdf (solid angle) proportional to the map's luminance; `radiance`, when given,
  // receives lighting() of the direction, read from the sampled texel.
  Vec3 sample(Vec2 u, float* pdf, Rgb* radiance = nullptr) const;
  float pdf(const Vec3& dir) const;
  Rgb average() const { return average_; }
  int width() const { return width_; }
  int height() const { return height_; }

  static Vec2 direction_to_uv(const Vec3& dir);
  static Vec3 uv_to_direction(Vec2 uv);

 private:
  EnvironmentMap(int width, int height);  // cells allocated, to be filled before build()
  void build();
  Rgb texel(int x, int y) const;
  Rgb lookup_uv(Vec2 uv) const;
  struct TexelIndex {
    int col, row;
  };
  TexelIndex texel_of(const Vec3& dir) const;  // the texel a direction falls in
  // Solid-angle density in texel (col, row) of a direction whose y (cos theta) is `cos_theta`.
  float pdf_cell(int col, int row, float cos_theta) const;
  int width_, height_;
  Distribution2D distribution_;  // the radiance, and a density over (u, v) proportional to luminance x sin(theta)
  Rgb average_;
};

struct Environment {
  Rgb color{0, 0, 0};  // constant radiance, or a tint of the map
  float intensity = 1;
  std::shared_ptr<const EnvironmentMap> map;
  float rotation_deg = 0;  // rotation of the map about +y

  // The radiance seen from `dir` (by the camera, or along mirror and glass paths from it).
  Rgb radiance(const Vec3& dir) const {
    if (!map) return color * intensity;
    return map->lookup(to_map(dir)) * color * intensity;
  }
  // The radiance that lights a surface from `dir` (what light sampling estimates), and the density of `dir` under
  // the environment's own sampling (the map's, or uniform on the sphere), from one read of the map.
  Rgb lighting(const Vec3& dir, float* pdf_dir) const {
    if (!map) {
      *pdf_dir = uniform_sphere_pdf();
      return color * intensity;
    }
    return map->lighting(to_map(dir), pdf_dir) * color * intensity;
  }
  // Samples a direction towards the environment, with density *pdf_dir (solid angle): by the map's luminance, or
  // uniformly on the sphere without a map; *le_out receives the radiance arriving from it, read from the sampled texel
  // rather than looked up again (PBR 4th ed. §12.5.2, image infinite lights). Light sampling and light emission (for
  // light tracing and BDPT) both draw their environment directions here.
  Vec3 sample_direction(Vec2 u, float* pdf_dir, Rgb* le_out) const {
    if (!map) {
      *pdf_dir = uniform_sphere_pdf();
      *le_out = color * intensity;
      return sample_uniform_sphere(u);
    }
    Rgb le;
    const Vec3 wi = from_map(map->sample(u, pdf_dir, &le));
    *le_out = le * color * intensity;
    return wi;
  }
  // The density with which sample_direction() draws `dir`.
  float direction_pdf(const Vec3& dir) const { return map ? map->pdf(to_map(dir)) : uniform_sphere_pdf(); }
  bool black() const { return intensity == 0 || is_black(color); }
  Rgb average() const { return map ? map->average() * color * intensity : color * intensity; }

  Vec3 to_map(const Vec3& d) const { return rotate(d, -rotation_deg); }
  Vec3 from_map(const Vec3& d) const { return rotate(d, rotation_deg); }

 private:
  static Vec3 rotate(const Vec3& d, float deg) {
    if (deg == 0) return d;
    float a = deg * kPi / 180, c = std::cos(a), s = std::sin(a);
    return Vec3(c * d.x + s * d.z, d.y, -s * d.x + c * d.z);
  }
};

}  // namespace tessera
