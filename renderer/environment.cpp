#include "renderer/environment.h"

#include <array>
#include <stdexcept>

#include "renderer/image_io.h"

namespace tessera {

// Map coordinates: u = 0.5 + atan2(x, -z) / 2pi (u = 0.5 looks down -z), v = acos(y) / pi (v = 0 at +y), with
// acos(y) as atan2(sqrt(x^2 + z^2), y): the same angle for a unit vector, and well conditioned at the poles.
Vec2 EnvironmentMap::direction_to_uv(const Vec3& d) {
  float u = 0.5f + fast_atan2(d.x, -d.z) * kInv2Pi;
  float v = fast_atan2(std::sqrt(d.x * d.x + d.z * d.z), d.y) * kInvPi;
  return {u - std::floor(u), v};
}

Vec3 EnvironmentMap::uv_to_direction(Vec2 uv) {
  float phi = (uv.x - 0.5f) * 2 * kPi;
  float theta = uv.y * kPi;
  float st = std::sin(theta);
  return {st * std::sin(phi), std::cos(theta), -st * std::cos(phi)};
}

EnvironmentMap::EnvironmentMap(int width, int height, std::vector<float> rgb) : EnvironmentMap(width, height) {
  if (rgb.size() != static_cast<size_t>(width_) * static_cast<size_t>(height_) * 3)
    throw std::invalid_argument("EnvironmentMap: the radiance array does not match the size");
  Distribution2D::Cell* cells = distribution_.cells();
  for (size_t i = 0; i < rgb.size() / 3; ++i) cells[i].value = Rgb(rgb[3 * i], rgb[3 * i + 1], rgb[3 * i + 2]);
  rgb = {};  // not held through the build
  build();
}

EnvironmentMap::EnvironmentMap(int width, int height) : width_(width), height_(height) {
  if (width_ < 2 || height_ < 1) throw std::invalid_argument("the environment map is too small");
  distribution_ = Distribution2D(width_, height_);
}

void EnvironmentMap::build() {
  // Radiance is made safe in place (not finite or negative: 0; above kMaxRadiance: clamped). The sampling weights
  // are made row by row as the distribution builds its rows (in parallel; a 4k map has 8 million texels), never held
  // whole. Each row's radiance sums are kept apart and added in row order: the same average whatever the number of
  // threads.
  std::vector<std::array<double, 4>> row_sums(height_);
  distribution_.build([&](int y, Distribution2D::Cell* row, float* weights) {
    // Each texel covers a solid angle proportional to sin(theta) at its centre.
    const float sin_theta = std::sin((y + 0.5f) * kPi / height_);
    double r = 0, g = 0, b = 0;
    for (int x = 0; x < width_; ++x) {
      Rgb& c = row[x].value;
      for (int k = 0; k < 3; ++k) c[k] = std::isfinite(c[k]) && c[k] > 0 ? std::min(c[k], kMaxRadiance) : 0.0f;
      // A small floor keeps every direction with radiance possible to sample.
      weights[x] = (luminance(c) + 1e-6f) * sin_theta;
      r += c.x;
      g += c.y;
      b += c.z;
    }
    row_sums[y] = {r * sin_theta, g * sin_theta, b * sin_theta, static_cast<double>(width_) * sin_theta};
  });
  double sum_r = 0, sum_g = 0, sum_b = 0, solid = 0;
  for (const std::array<double, 4>& s : row_sums) {
    sum_r += s[0];
    sum_g += s[1];
    sum_b += s[2];
    solid += s[3];
  }
  average_ = solid > 0 ? Rgb(static_cast<float>(sum_r / solid), static_cast<float>(sum_g / solid),
                             static_cast<float>(sum_b / solid))
                       : Rgb(0);
}

void EnvironmentMap::check(const std::string& path) {
  const ImageHeader header = read_image_header(path, kMaxTexels, Distribution2D::kMaxWidth);
  if (header.width < 2) throw std::runtime_error("the environment map is too small");
}

std::shared_ptr<EnvironmentMap> EnvironmentMap::load(const std::string& path) {
  // RGB read straight into the map's cells (grey repeated, alpha left on disk), then made safe in place. The size is
  // checked from the header, before anything is allocated: 16384 x 8192 texels at most.
  std::shared_ptr<EnvironmentMap> map;
  read_image_into(path, 3, sizeof(Distribution2D::Cell) / sizeof(float), kMaxTexels, Distribution2D::kMaxWidth,
                  [&](int width, int height) {
                    if (width < 2 || height < 1) throw std::runtime_error("the environment map is too small");
                    map.reset(new EnvironmentMap(width, height));
                    return &map->distribution_.cells()->value.x;
                  });
  map->build();
  return map;
}

Rgb EnvironmentMap::texel(int x, int y) const {
  // Lookups ask for at most one texel past either edge; the modulo (an integer division) is for anything else.
  if (x < 0)
    x += width_;
  else if (x >= width_)
    x -= width_;
  if (x < 0 || x >= width_) x = ((x % width_) + width_) % width_;
  y = clamp(y, 0, height_ - 1);
  return distribution_.cell(x, y).value;
}

Rgb EnvironmentMap::lookup_uv(Vec2 uv) const {
  float fx = uv.x * width_ - 0.5f, fy = uv.y * height_ - 0.5f;
  int x0 = static_cast<int>(std::floor(fx)), y0 = static_cast<int>(std::floor(fy));
  float tx = fx - x0, ty = fy - y0;
  return texel(x0, y0) * ((1 - tx) * (1 - ty)) + texel(x0 + 1, y0) * (tx * (1 - ty)) +
         texel(x0, y0 + 1) * ((1 - tx) * ty) + texel(x0 + 1, y0 + 1) * (tx * ty);
}

Rgb EnvironmentMap::lighting(const Vec3& dir, float* pdf) const {
  const TexelIndex at = texel_of(dir);
  *pdf = pdf_cell(at.col, at.row, dir.y);
  return distribution_.cell(at.col, at.row).value;
}

Vec3 EnvironmentMap::sample(Vec2 u, float* pdf, Rgb* radiance) const {
  float pdf_uv = 0;
  const Distribution2D::Cell* cell = nullptr;
  const Vec2 uv = distribution_.sample(u, &pdf_uv, &cell);
  Vec3 dir = uv_to_direction(uv);
  float sin_theta = std::sin(uv.y * kPi);
  // dω = 2π² sinθ du dv.
  *pdf = sin_theta > 0 ? pdf_uv / (2 * kPi * kPi * sin_theta) : 0.0f;
  if (radiance) *radiance = cell->value;
  return dir;
}

float EnvironmentMap::pdf(const Vec3& dir) const {
  const TexelIndex at = texel_of(dir);
  return pdf_cell(at.col, at.row, dir.y);
}

EnvironmentMap::TexelIndex EnvironmentMap::texel_of(const Vec3& dir) const {
  const Vec2 uv = direction_to_uv(dir);
  return {std::min(width_ - 1, static_cast<int>(uv.x * width_)),
          std::min(height_ - 1, static_cast<int>(uv.y * height_))};
}

float EnvironmentMap::pdf_cell(int col, int row, float cos_theta) const {
  // sin(theta) from cos(theta) as sqrt((1 - c)(1 + c)), which keeps its precision near the poles.
  const float c = clamp(cos_theta, -1.0f, 1.0f);
  float sin_theta = safe_sqrt((1 - c) * (1 + c));
  if (sin_theta <= 0) return 0;
  return distribution_.pdf(col, row) / (2 * kPi * kPi * sin_theta);
}

}  // namespace tessera
