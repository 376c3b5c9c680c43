#include "bsdf_harness.h"

#include <algorithm>
#include <cmath>
#include <functional>

namespace tessera::test {

using nlohmann::json;

const std::vector<BsdfCase>& bsdf_cases() {
  static const std::vector<BsdfCase> cases = {
      {"lambert", {{"type", "lambert"}, {"albedo", 0.8}}},
      {"phong_broad", {{"type", "phong"}, {"kd", 0.3}, {"ks", 0.7}, {"exponent", 2}}},
      {"phong_sharp", {{"type", "phong"}, {"kd", 0.1}, {"ks", 0.9}, {"exponent", 400}}},
      {"blinn_phong_broad", {{"type", "blinn_phong"}, {"kd", 0.5}, {"ks", 0.5}, {"exponent", 1}}},
      {"blinn_phong_sharp", {{"type", "blinn_phong"}, {"kd", 0}, {"ks", 1}, {"exponent", 800}}},
      {"phong_classic", {{"type", "phong_classic"}, {"kd", 0.2}, {"ks", 0.8}, {"exponent", 20}}},
      {"blinn_phong_classic", {{"type", "blinn_phong_classic"}, {"kd", 0.2}, {"ks", 0.8}, {"exponent", 20}}},
      {"ct_beckmann_smith_low", {{"type", "cook_torrance"}, {"distribution", "beckmann"}, {"roughness", 0.05}}},
      {"ct_beckmann_vcavity",
       {{"type", "cook_torrance"},
        {"distribution", "beckmann"},
        {"masking", "v_cavity"},
        {"roughness", 0.3},
        {"kd", 0.4},
        {"ks", 0.6}}},
      {"ct_ggx_high",
       {{"type", "cook_torrance"},
        {"distribution", "ggx"},
        {"roughness", 1.0},
        {"fresnel", "conductor"},
        {"metal", "copper"}}},
      {"ct_ggx_aniso", {{"type", "cook_torrance"}, {"distribution", "ggx"}, {"alpha_x", 0.05}, {"alpha_y", 0.6}}},
      {"ct_beckmann_aniso_vcavity",
       {{"type", "cook_torrance"},
        {"distribution", "beckmann"},
        {"masking", "v_cavity"},
        {"alpha_x", 0.6},
        {"alpha_y", 0.08},
        {"kd", 0.2},
        {"ks", 0.8}}},
      {"ward_iso", {{"type", "ward"}, {"rho_d", 0.3}, {"rho_s", 0.6}, {"alpha", 0.1}}},
      {"ward_aniso", {{"type", "ward"}, {"rho_d", 0.1}, {"rho_s", 0.9}, {"alpha_x", 0.05}, {"alpha_y", 0.5}}},
      {"ward_original", {{"type", "ward"}, {"normalisation", "ward"}, {"alpha", 0.3}}},
      {"dielectric_ggx_low", {{"type", "dielectric"}, {"roughness", 0.05}, {"ior", 1.5}}, true},
      {"dielectric_ggx_mid", {{"type", "dielectric"}, {"roughness", 0.4}, {"ior", 1.5}}, true},
      {"dielectric_beckmann_high",
       {{"type", "dielectric"}, {"distribution", "beckmann"}, {"roughness", 1.0}, {"ior", 1.33}},
       true},
      {"dielectric_ggx_aniso", {{"type", "dielectric"}, {"alpha_x", 0.08}, {"alpha_y", 0.6}, {"ior", 2.0}}, true},
      {"conductor_ggx_low", {{"type", "conductor"}, {"roughness", 0.05}, {"metal", "gold"}}},
      {"conductor_beckmann_high",
       {{"type", "conductor"}, {"distribution", "beckmann"}, {"roughness", 1.0}, {"metal", "iron"}}},
      {"conductor_ggx_aniso", {{"type", "conductor"}, {"alpha_x", 0.6}, {"alpha_y", 0.05}, {"metal", "aluminium"}}},
      {"plastic_smooth", {{"type", "plastic"}, {"diffuse", 0.7}}},
      {"plastic_rough_low", {{"type", "plastic"}, {"diffuse", 0.5}, {"roughness", 0.05}}},
      {"plastic_rough_high", {{"type", "plastic"}, {"diffuse", 0.9}, {"roughness", 1.0}, {"distribution", "beckmann"}}},
      {"gltf_dielectric", {{"type", "gltf_pbr"}, {"metallic", 0}, {"roughness", 0.5}, {"base_color", {0.8, 0.3, 0.2}}}},
      {"gltf_metal_low", {{"type", "gltf_pbr"}, {"metallic", 1}, {"roughness", 0.2}}},
      {"gltf_rough", {{"type", "gltf_pbr"}, {"metallic", 0.5}, {"roughness", 1.0}}},
      {"gltf_transmission",
       {{"type", "gltf_pbr"}, {"metallic", 0}, {"roughness", 0.3}, {"transmission", 0.8}, {"ior", 1.45}}},
      {"gltf_solid_transmission",
       {{"type", "gltf_pbr"},
        {"metallic", 0.1},
        {"roughness", 0.3},
        {"transmission", 0.9},
        {"ior", 1.5},
        {"base_color", {0.9, 0.7, 0.5}},
        {"thin_walled", false}},
       true},
      // Subsurface: a solid whose refracting lobe is the transmission's share tinted by the base colour and the
      // subsurface share untinted (the subsurface volume's colour is the medium's).
      {"gltf_subsurface",
       {{"type", "gltf_pbr"},
        {"metallic", 0},
        {"roughness", 0.4},
        {"transmission", 0.3},
        {"subsurface_weight", 0.6},
        {"thin_walled", false},
        {"ior", 1.4},
        {"base_color", {0.8, 0.3, 0.2}}},
       true},
      {"gltf_clearcoat_specular",
       {{"type", "gltf_pbr"},
        {"metallic", 0},
        {"roughness", 0.8},
        {"clearcoat", 1},
        {"clearcoat_roughness", 0.1},
        {"specular", 0.5},
        {"specular_color", {1, 0.5, 0.5}}}},
      {"gltf_tilted_clearcoat",
       {{"type", "gltf_pbr"},
        {"metallic", 0.3},
        {"roughness", 0.5},
        {"clearcoat", 0.8},
        {"clearcoat_roughness", 0.2},
        {"base_color", {0.5, 0.6, 0.7}}},
       false,
       normalize(Vec3(0.5f, 0.2f, 1))},
      {"gltf_sheen",
       {{"type", "gltf_pbr"},
        {"metallic", 0},
        {"roughness", 0.6},
        {"sheen_color", {1.0, 0.8, 0.9}},
        {"sheen_roughness", 0.3}}},
      {"gltf_sheen_sharp_coated",
       {{"type", "gltf_pbr"},
        {"metallic", 0},
        {"roughness", 0.2},
        {"base_color", 1.0},
        {"sheen_color", 1.0},
        {"sheen_roughness", 0.1},
        {"clearcoat", 0.5},
        {"clearcoat_roughness", 0.3}}},
      {"gltf_anisotropic_metal",
       {{"type", "gltf_pbr"}, {"metallic", 1}, {"roughness", 0.3}, {"anisotropy", 0.8}, {"anisotropy_rotation", 0.6}}},
      {"gltf_anisotropic_coated",
       {{"type", "gltf_pbr"},
        {"metallic", 0.2},
        {"roughness", 0.4},
        {"anisotropy", 0.6},
        {"anisotropy_rotation", -1.2},
        {"clearcoat", 0.7},
        {"clearcoat_roughness", 0.2},
        {"base_color", {0.6, 0.5, 0.4}}},
       false,
       normalize(Vec3(0.4f, -0.3f, 1))},
      {"gltf_iridescent_metal",
       {{"type", "gltf_pbr"},
        {"metallic", 1},
        {"roughness", 0.35},
        {"base_color", {0.9, 0.6, 0.3}},
        {"iridescence", 0.8},
        {"iridescence_ior", 1.8},
        {"iridescence_thickness_minimum", 200},
        {"iridescence_thickness_maximum", 500}}},
      {"gltf_iridescent_dielectric",
       {{"type", "gltf_pbr"},
        {"metallic", 0},
        {"roughness", 0.4},
        {"base_color", {0.8, 0.8, 0.7}},
        {"iridescence", 0.9},
        {"iridescence_ior", 1.8},
        {"iridescence_thickness_maximum", 300}}},
      {"gltf_diffuse_transmission",
       {{"type", "gltf_pbr"},
        {"metallic", 0.1},
        {"roughness", 0.4},
        {"base_color", {0.7, 0.5, 0.3}},
        {"diffuse_transmission", 0.6},
        {"diffuse_transmission_color", {0.3, 0.8, 0.4}},
        {"transmission", 0.3}},
       true},
      {"mix_lambert_conductor",
       {{"type", "mix"},
        {"a", {{"type", "lambert"}, {"albedo", 0.5}}},
        {"b", {{"type", "conductor"}, {"roughness", 0.2}}},
        {"weight", 0.3}}},
      {"mix_with_delta",
       {{"type", "mix"},
        {"a", {{"type", "dielectric"}}},
        {"b", {{"type", "cook_torrance"}, {"distribution", "ggx"}, {"roughness", 0.3}}},
        {"weight", 0.6}},
       true},
      {"two_sided_rough_dielectric",
       {{"type", "two_sided"}, {"material", {{"type", "dielectric"}, {"roughness", 0.3}}}},
       true},
  };
  return cases;
}

const std::vector<std::string>& delta_only_types() {
  static const std::vector<std::string> types = {"emission", "thin_dielectric", "interface"};
  return types;
}

bool is_classic(const std::string& type) {
  return type == "phong_classic" || type == "blinn_phong_classic";
}

Vec3 direction(float theta_deg, float phi_deg) {
  float t = theta_deg * kPi / 180, p = phi_deg * kPi / 180;
  return {std::sin(t) * std::cos(p), std::sin(t) * std::sin(p), std::cos(t)};
}

std::vector<Vec3> incident_directions(const BsdfCase& c) {
  std::vector<Vec3> out = {direction(5, 37), direction(35, 37), direction(65, 100), direction(87, 37)};
  if (c.transmissive) {
    out.push_back(direction(160, 37));  // from inside, refracts
    out.push_back(direction(125, 37));  // from inside, past the critical angle for ior >= 1.33: total reflection
  } else {
    out.push_back(direction(130, 37));  // the back side of a two-sided reflector
  }
  return out;
}

std::vector<Vec3> albedo_directions() {
  std::vector<Vec3> out;
  for (int i = 0; i < 10; ++i) out.push_back(direction(static_cast<float>(i) * 88.0f / 9.0f, 23));
  return out;
}

int chi2_test_count() {
  int n = 0;
  for (const BsdfCase& c : bsdf_cases()) n += static_cast<int>(incident_directions(c).size());
  return n;
}

BsdfInstance::BsdfInstance(const json& material, const Vec3& coat_normal) {
  MaterialContext ctx;
  material_ = MaterialRegistry::builtin().create(material, "/material", ctx);
  sp_.frame = Frame();
  sp_.ng = Vec3(0, 0, 1);
  sp_.uv = sp_.uv1 = Vec2(0.5f, 0.5f);
  sp_.coat_normal = coat_normal;
  bsdf_ = material_->bsdf(sp_, arena_);
}

namespace {

constexpr int kRows = 80;   // cos theta in [-1, 1]
constexpr int kCols = 160;  // phi in [0, 2 pi)

double pdf_at(const Bsdf& bsdf, const Vec3& wo, double cos_theta, double phi) {
  double s = std::sqrt(std::max(0.0, 1 - cos_theta * cos_theta));
  Vec3 wi(static_cast<float>(s * std::cos(phi)), static_cast<float>(s * std::sin(phi)), static_cast<float>(cos_theta));
  return bsdf.pdf(wo, wi);
}

// Adaptive Simpson cubature over [x0,x1] x [y0,y1]: the 3x3 Simpson rule against its four half-size copies, split
// where they disagree.
double simpson_3x3(const double f[3][3], double hx, double hy) {
  static const double w[3] = {1, 4, 1};
  double sum = 0;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) sum += w[i] * w[j] * f[i][j];
  return sum * hx * hy / 36.0;
}

double adaptive(const std::function<double(double, double)>& g, double x0, double x1, double y0, double y1,
                const double f[3][3], double whole, double tol, int depth) {
  double mx = 0.5 * (x0 + x1), my = 0.5 * (y0 + y1);
  // 5x5 grid: reuse the 3x3 values at even indices.
  double v[5][5];
  for (int i = 0; i < 5; ++i)
    for (int j = 0; j < 5; ++j) {
      if (i % 2 == 0 && j % 2 == 0)
        v[i][j] = f[i / 2][j / 2];
      else
        v[i][j] = g(x0 + (x1 - x0) * i / 4.0, y0 + (y1 - y0) * j / 4.0);
    }
  double parts[4];
  double sub[4][3][3];
  for (int q = 0; q < 4; ++q) {
    int oi = (q & 1) * 2, oj = (q >> 1) * 2;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) sub[q][i][j] = v[oi + i][oj + j];
    parts[q] = simpson_3x3(sub[q], 0.5 * (x1 - x0), 0.5 * (y1 - y0));
  }
  double refined = parts[0] + parts[1] + parts[2] + parts[3];
  if (depth <= 0 || std::abs(refined - whole) <= 15 * tol) return refined + (refined - whole) / 15;
  double out = 0;
  for (int q = 0; q < 4; ++q) {
    double qx0 = (q & 1) ? mx : x0, qx1 = (q & 1) ? x1 : mx;
    double qy0 = (q >> 1) ? my : y0, qy1 = (q >> 1) ? y1 : my;
    out += adaptive(g, qx0, qx1, qy0, qy1, sub[q], parts[q], tol / 4, depth - 1);
  }
  return out;
}

double integrate_cell(const std::function<double(double, double)>& g, double x0, double x1, double y0, double y1,
                      double tol) {
  double f[3][3];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) f[i][j] = g(x0 + (x1 - x0) * i / 2.0, y0 + (y1 - y0) * j / 2.0);
  double whole = simpson_3x3(f, x1 - x0, y1 - y0);
  return adaptive(g, x0, x1, y0, y1, f, whole, tol, 7);
}

}  // namespace

Chi2Result chi2_test(const Bsdf& bsdf, const Vec3& wo, int n, uint64_t seed) {
  Chi2Result r;
  std::vector<double> observed(kRows * kCols, 0.0);
  double other = 0;  // discarded or delta samples
  std::mt19937_64 rng(seed);
  for (int i = 0; i < n; ++i) {
    float uc = uniform01(rng);
    Vec2 u(uniform01(rng), uniform01(rng));
    std::optional<BsdfSample> s = bsdf.sample(wo, uc, u);
    if (!s || is_delta(s->flags)) {
      other += 1;
      continue;
    }
    Vec3 wi = s->wi;
    if (!(bsdf.pdf(wo, wi) > 0) && r.failure.empty()) {
      r.failure = "sample() returned a non-delta direction where pdf() is zero: wi = (" + std::to_string(wi.x) + ", " +
                  std::to_string(wi.y) + ", " + std::to_string(wi.z) + ")";
    }
    double z = clamp(static_cast<double>(wi.z), -1.0, 1.0);
    double phi = std::atan2(static_cast<double>(wi.y), static_cast<double>(wi.x));
    if (phi < 0) phi += 2 * M_PI;
    int row = std::min(kRows - 1, static_cast<int>((z + 1) * 0.5 * kRows));
    int col = std::min(kCols - 1, static_cast<int>(phi / (2 * M_PI) * kCols));
    observed[row * kCols + col] += 1;
  }
  r.sampled_fraction = 1 - other / n;

  std::vector<double> expected(kRows * kCols, 0.0);
  auto g = [&](double z, double phi) { return pdf_at(bsdf, wo, z, phi); };
  double total = 0;
  for (int row = 0; row < kRows; ++row) {
    double z0 = -1 + 2.0 * row / kRows, z1 = -1 + 2.0 * (row + 1) / kRows;
    for (int col = 0; col < kCols; ++col) {
      double p0 = 2 * M_PI * col / kCols, p1 = 2 * M_PI * (col + 1) / kCols;
      double v = integrate_cell(g, z0, z1, p0, p1, 1e-8);
      expected[row * kCols + col] = v * n;
      total += v;
    }
  }
  r.pdf_integral = total;

  // Pool cells expecting fewer than 5 (together with the "other" cell when it is small).
  struct Cell {
    double e, o;
  };
  std::vector<Cell> cells;
  for (size_t i = 0; i < expected.size(); ++i) {
    cells.push_back({expected[i], observed[i]});
  }
  cells.push_back({std::max(0.0, 1 - total) * n, other});
  std::sort(cells.begin(), cells.end(), [](const Cell& a, const Cell& b) { return a.e < b.e; });
  double pooled_e = 0, pooled_o = 0, chi2 = 0;
  int bins = 0;
  for (const Cell& c : cells) {
    if (c.e < 5) {
      pooled_e += c.e;
      pooled_o += c.o;
      if (pooled_e >= 5) {
        chi2 += (pooled_o - pooled_e) * (pooled_o - pooled_e) / pooled_e;
        ++bins;
        pooled_e = pooled_o = 0;
      }
      continue;
    }
    chi2 += (c.o - c.e) * (c.o - c.e) / c.e;
    ++bins;
  }
  if (pooled_e > 0) {
    chi2 += (pooled_o - pooled_e) * (pooled_o - pooled_e) / std::max(pooled_e, 1e-3);
    ++bins;
  }
  r.statistic = chi2;
  r.dof = std::max(1, bins - 1);
  r.p_value = gamma_q(r.dof / 2.0, chi2 / 2.0);
  return r;
}

void PrintTo(const BsdfCase& c, std::ostream* os) {
  *os << c.name;
}

}  // namespace tessera::test
