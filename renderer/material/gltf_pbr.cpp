// The glTF 2.0 metallic-roughness material (glTF 2.0 specification, appendix B "BRDF Implementation"), with the
// extensions KHR_materials_ior, KHR_materials_specular, KHR_materials_transmission, KHR_materials_sheen,
// KHR_materials_clearcoat, KHR_materials_anisotropy, KHR_materials_diffuse_transmission and
// KHR_materials_iridescence (the last three described at the end):
//
//   alpha = roughness^2; D = GGX (Trowbridge-Reitz), V = G2 / (4 |N.L| |N.V|) with height-correlated Smith G2
//   dielectric F_d = Schlick(f0_d, f90_d, V.H), f0_d = min(((ior-1)/(ior+1))^2 * specular_color, 1) * specular,
//                    f90_d = specular                            (KHR_materials_ior / KHR_materials_specular;
//                                                                  f0 = 0.04 for the default ior 1.5)
//   metal F_m      = Schlick(base_color, 1, V.H)                  (appendix B, "conductor_fresnel")
//   f = (1 - metallic) [ (1 - transmission) W base_color / pi                  (diffuse, "fresnel_mix")
//                        + F_d D V
//                        + transmission (1 - max(F_d)) base_color D V (mirrored) ]  (thin-walled specular BTDF)
//     + metallic F_m D V
//   sheen:  f min(1 - max(sheen_color) E_sh(mu_o), 1 - max(sheen_color) E_sh(mu_i)) + sheen_color D_sh V_sh,
//           D_sh the "Charlie" distribution (2 + 1/a) sin(theta_h)^(1/a) / (2 pi), a = sheen_roughness^2
//           (Estevez & Kulla 2017), V_sh = 1 / (4 (N.L + N.V - N.L N.V)) (Neubelt & Pettineo 2013), E_sh its
//           tabulated albedo (KHR_materials_sheen, "albedo scaling"); the Charlie lobe's own albedo exceeds 1 at
//           grazing angles, so tessera divides it by max(1, E_sh(mu_o), E_sh(mu_i)) and caps E_sh at 1 in the
//           scaling: reciprocal, and the sum stays at most 1
//   coated: f min(1 - clearcoat E_c(mu_o), 1 - clearcoat E_c(mu_i)) + clearcoat F_c(V.H) D_c V_c,
//           F_c = Schlick(0.04, 1, V.H), alpha_c = clearcoat_roughness^2   (KHR_materials_clearcoat, "fresnel_coat");
//           the coat's cosines, D_c and V_c taken about its own normal (clearcoatNormalTexture), which may differ
//           from the base's
// Energy: the appendix's diffuse weight W = 1 - max(F_d(V.H)) gains energy at grazing angles (measured here: albedo
// up to 1.34 for a white rough dielectric at 88 degrees), because the specular lobe's albedo E_s(mu) grows faster
// than the average of F over the diffuse directions falls. tessera therefore couples the diffuse lobe to the
// specular one by their albedos (Kelemen & Szirmay-Kalos 2001, eq. 8; Kulla & Conty 2017):
//   W = (1 - E_s(mu_o)) (1 - E_s(mu_i)) / (1 - E_s_avg),
// with E_s = f0 E_1(mu, alpha) + f90 E_2(mu, alpha) from a precomputed table of GGX + Schlick albedos (the "split
// sum" of Karis 2013), so that a white base has albedo E_s(mu_o) + (1 - E_s(mu_o)) = 1 at every angle. The
// clearcoat attenuates what is under it by the coat's albedo E_c the same way, with the min keeping it reciprocal
// and bounded.
// The transmission lobe is the thin-walled one of KHR_materials_transmission without KHR_materials_volume: the
// reflection lobe mirrored through the surface (no refraction). The half vector of a transmitted pair is that of
// its mirrored pair, so every term is symmetric in wo and wi (reciprocal), and with Fresnel weights <= 1 and
// single-scattering microfacet lobes the albedo is at most 1 (energy is lost, not gained, at high roughness).
// Roughness below 0.002 (alpha 4e-6) is clamped there: the model has no delta lobes, and a lobe that narrow spreads a
// reflected or transmitted ray by micro-radians, so a smooth surface is a sharp mirror and a smooth thin wall clear
// glass (a floor of alpha 0.002 would blur what is seen through such a wall by several pixels: the lobe itself, and the
// texture footprint of the ray cone its density widens). GGX is evaluated in its tangent form (microfacet.cpp),
// which float keeps accurate at that alpha.
// Solid transmission ("thin_walled": false; glTF KHR_materials_volume with a thicknessFactor above 0): the object is
// a dielectric volume, and the transmission lobe is the rough dielectric interface of Walter et al. 2007
// (rough_dielectric.h) at the material's IOR, its transmitted part tinted by the base colour: glTF's
//   dielectric_brdf = mix(fresnel_mix(ior, diffuse, specular_brdf), fresnel_mix(ior, specular_btdf, specular_brdf),
//                         transmission)
// (KHR_materials_transmission, "Implementation"; KHR_materials_volume, "Refraction"), with the second fresnel_mix
// the interface itself: rays refract in by Snell's law (on average over the microfacets), travel inside, and refract
// out or reflect totally from inside. Its reflection takes the place of the (1 - metallic) transmission share of the
// F_d D V lobe. Across it the BSDF is the radiance form (1/eta'^2, Veach 1997, 5.2); the adjoint takes that out. The
// transmission lobe's roughness is scaled by clamp(2 ior - 2, 0, 1), as the Khronos glTF Sample Viewer does
// (applyIorToRoughness): at IOR 1 nothing refracts, so a rough pane stays clear; at 1.5 the lobe is as rough as the
// reflection.
// KHR_materials_dispersion: a solid's index varies with the wavelength (spectrum.h's dispersive_ior, the extension's
// Cauchy form from the Abbe number); the BSDF refracts and reflects by its index at the wavelength the path carries.
// KHR_materials_anisotropy: the specular and metal lobes are anisotropic GGX with alpha_t = mix(alpha, 1,
// strength^2) along the anisotropy direction and alpha_b = alpha across it (the extension's "Implementation"); the
// direction is the tangent rotated in the tangent plane by the rotation (and by the texture's RG direction). The BSDF
// works in that direction's frame (every other lobe is isotropic about the normal; the coat's normal is turned with
// it). The albedo tables keep the isotropic alpha_b: the specular albedo they give is then at least the anisotropic
// lobe's, so the diffuse lobe's coupling weight errs towards losing energy, not gaining it.
// KHR_materials_diffuse_transmission: the diffuse lobe is mix(diffuse_brdf(base_color),
// diffuse_btdf(diffuse_transmission_color), diffuse_transmission) (the extension's "BTDF"), the BTDF a Lambertian lobe
// into the opposite hemisphere with the same albedo coupling W as the reflection, so a white base that transmits
// everything keeps albedo 1 (reflection plus transmission) and stays reciprocal. Thin-walled: on a solid (refracting)
// surface it is not drawn (the loader warns).
// KHR_materials_iridescence: the specular Fresnel terms, dielectric and metal, become mix(F, F_film, iridescence),
// F_film the reflectance of the base (f0_d, or base_color for the metal) under a thin dielectric film of index
// iridescence_ior and thickness mix(minimum, maximum, texture) nanometres at V.H (Belcour & Barla 2017; the
// extension's appendix), fresnel.h's fresnel_thin_film. The thin-walled BTDF passes 1 - max(F) of the same mix. The
// diffuse lobe's coupling W needs the specular lobe's albedo under the film, which the Schlick tables do not hold: a
// film reflects up to several times the bare base's f0 (a white dielectric under a 120 nm film of index 1.8 had albedo
// 1.13 with Schlick's). E_s is linear in f0, and a Schlick curve f0' + (f90 - f0')(1 - c)^5 that lies above F_film at
// every angle bounds the film lobe's albedo from above, so W takes E_s of mix(f0_d, f0', iridescence), with f0' the
// least such f0 over seven angles (cos 1 to 0.1) per channel: energy is lost, not gained, where the film reflects
// less than its bound. The lobe probabilities keep Schlick's Fresnel (they are sampling weights only).
// Subsurface (OpenPBR's subsurface lobe; subsurface.h): a solid's dielectric base is mix(mix(diffuse, subsurface,
// subsurface_weight), translucent, transmission); the subsurface share refracts, untinted, through the transmission
// lobe's interface into the interior medium, where the path tracer random-walks until it leaves. The two refracting
// shares are one lobe of weight t + (1 - t) subsurface_weight, tinted by their weighted mean colour.
#include "renderer/bsdf/fresnel.h"
#include "renderer/bsdf/rough_dielectric.h"
#include "renderer/material/common.h"
#include "renderer/material/subsurface.h"
#include "renderer/sampling.h"
#include "renderer/scene_error.h"
#include "renderer/spectrum.h"
#include "renderer/thread_pool.h"

namespace tessera {
namespace {

// Directional albedo of the GGX lobe with Schlick Fresnel split into its f0 and f90 parts,
//   E(mu, alpha) = f0 E_1(mu, alpha) + f90 E_2(mu, alpha), E_1 = \int (1 - (1 - c)^5) D V cos, E_2 = \int (1 - c)^5
//   ...,
// tabulated over mu = cos(theta_o) and r = sqrt(alpha), with their cosine-weighted averages over mu.
class SchlickAlbedoTable {
 public:
  static const SchlickAlbedoTable& get() {
    static const SchlickAlbedoTable table;
    return table;
  }
  // Returns E_1, E_2 at (mu, alpha).
  void eval(float mu, float alpha, float* e1, float* e2) const {
    float x = clamp(mu, 0.0f, 1.0f) * (kN - 1), y = clamp(std::sqrt(alpha), 0.0f, 1.0f) * (kN - 1);
    int i = std::min(static_cast<int>(x), kN - 2), j = std::min(static_cast<int>(y), kN - 2);
    float tx = x - i, ty = y - j;
    auto lerp2 = [&](const float(&t)[kN][kN]) {
      return (t[i][j] * (1 - tx) + t[i + 1][j] * tx) * (1 - ty) + (t[i][j + 1] * (1 - tx) + t[i + 1][j + 1] * tx) * ty;
    };
    *e1 = lerp2(e1_);
    *e2 = lerp2(e2_);
  }
  void average(float alpha, float* a1, float* a2) const {
    float y = clamp(std::sqrt(alpha), 0.0f, 1.0f) * (kN - 1);
    int j = std::min(static_cast<int>(y), kN - 2);
    float ty = y - j;
    *a1 = avg1_[j] * (1 - ty) + avg1_[j + 1] * ty;
    *a2 = avg2_[j] * (1 - ty) + avg2_[j + 1] * ty;
  }

 private:
  static constexpr int kN = 32;
  SchlickAlbedoTable() {
    const int n = 40;  // n x n stratified visible-normal samples per entry
    // Columns (roughnesses) are independent: made in parallel, each the same whatever thread makes it.
    run_in_parallel(kN, [&](size_t column) {
      const int j = static_cast<int>(column);
      MicrofacetDistribution d;
      d.type = MicrofacetType::kGgx;
      float r = static_cast<float>(j) / (kN - 1);
      d.alpha_x = d.alpha_y = std::max(r * r, 1e-3f);
      for (int i = 0; i < kN; ++i) {
        float mu = std::max(static_cast<float>(i) / (kN - 1), 1e-3f);
        Vec3 wo(std::sqrt(1 - mu * mu), 0, mu);
        double s1 = 0, s2 = 0;
        for (int a = 0; a < n; ++a)
          for (int b = 0; b < n; ++b) {
            Vec3 wi;
            if (!microfacet_reflection_sample(d, wo, Vec2((a + 0.5f) / n, (b + 0.5f) / n), 0.5f, &wi)) continue;
            float pdf = microfacet_reflection_pdf(d, wo, wi);
            if (!(pdf > 0)) continue;
            double w = microfacet_reflection_eval(d, wo, wi) * wi.z / pdf;
            const double m = 1.0 - std::min(1.0f, dot(wo, normalize(wo + wi))), m2 = m * m;
            const double c5 = m2 * m2 * m;
            s1 += w * (1 - c5);
            s2 += w * c5;
          }
        e1_[i][j] = static_cast<float>(s1 / (n * n));
        e2_[i][j] = static_cast<float>(s2 / (n * n));
      }
      // E_avg = 2 \int E(mu) mu dmu (trapezoidal rule over the table).
      double a1 = 0, a2 = 0;
      for (int i = 0; i + 1 < kN; ++i) {
        double m0 = static_cast<double>(i) / (kN - 1), m1 = static_cast<double>(i + 1) / (kN - 1);
        a1 += 0.5 * (e1_[i][j] * m0 + e1_[i + 1][j] * m1) * (m1 - m0);
        a2 += 0.5 * (e2_[i][j] * m0 + e2_[i + 1][j] * m1) * (m1 - m0);
      }
      avg1_[j] = static_cast<float>(2 * a1);
      avg2_[j] = static_cast<float>(2 * a2);
    });
  }
  float e1_[kN][kN];
  float e2_[kN][kN];
  float avg1_[kN];
  float avg2_[kN];
};

// The sheen lobe: Charlie distribution and Neubelt's visibility, and its directional albedo tabulated over
// (mu, sqrt(a)) by stratified cosine-weighted quadrature.
float charlie_d(float cos_h, float a) {
  float sin2 = std::max(0.0f, 1 - cos_h * cos_h);
  return (2 + 1 / a) * std::pow(sin2, 0.5f / a) * kInv2Pi;
}
float sheen_v(float cos_o, float cos_i) {
  return 1 / (4 * (cos_i + cos_o - cos_i * cos_o));
}
float sheen_eval(const Vec3& wo, const Vec3& wi, float a) {
  Vec3 h;
  if (wo.z <= 0 || wi.z <= 0 || !reflection_half_vector(wo, wi, &h)) return 0;
  return charlie_d(h.z, a) * sheen_v(wo.z, wi.z);
}

// E_sh(mu) = \int f_sh cos d(omega_i), tabulated over (sqrt(mu), sqrt(a)) (it changes fastest near grazing) by a
// midpoint rule in (mu_i = t^2, phi), which resolves grazing directions too.
class SheenAlbedoTable {
 public:
  static constexpr float kMinAlpha = 0.01f;
  static const SheenAlbedoTable& get() {
    static const SheenAlbedoTable table;
    return table;
  }
  float eval(float mu, float a) const {
    float x = std::sqrt(clamp(mu, 0.0f, 1.0f)) * (kN - 1), y = clamp(std::sqrt(a), 0.0f, 1.0f) * (kN - 1);
    int i = std::min(static_cast<int>(x), kN - 2), j = std::min(static_cast<int>(y), kN - 2);
    float tx = x - i, ty = y - j;
    return (e_[i][j] * (1 - tx) + e_[i + 1][j] * tx) * (1 - ty) +
           (e_[i][j + 1] * (1 - tx) + e_[i + 1][j + 1] * tx) * ty;
  }

 private:
  static constexpr int kN = 32;
  SheenAlbedoTable() {
    const int nt = 96, nphi = 48;  // phi over [0, pi]: the lobe is symmetric about the plane of incidence
    run_in_parallel(kN, [&](size_t column) {
      const int j = static_cast<int>(column);
      float r = static_cast<float>(j) / (kN - 1);
      float a = std::max(r * r, kMinAlpha);
      for (int i = 0; i < kN; ++i) {
        float s = static_cast<float>(i) / (kN - 1);
        float mu = std::max(s * s, 1e-4f);
        Vec3 wo(std::sqrt(1 - mu * mu), 0, mu);
        double sum = 0;
        for (int p = 0; p < nt; ++p) {
          float t = (p + 0.5f) / nt, mi = t * t, dmi = 2 * t / nt;
          float si = std::sqrt(std::max(0.0f, 1 - mi * mi));
          for (int q = 0; q < nphi; ++q) {
            float phi = (q + 0.5f) / nphi * kPi;
            Vec3 wi(si * std::cos(phi), si * std::sin(phi), mi);
            sum += sheen_eval(wo, wi, a) * mi * dmi * (kPi / nphi);
          }
        }
        e_[i][j] = static_cast<float>(2 * sum);
      }
    });
  }
  float e_[kN][kN];
};

// The least f0' per channel whose Schlick curve f0' + (f90 - f0')(1 - c)^5 lies above the thin-film Fresnel of a base
// of reflectance f0 (fresnel_thin_film, in air) at seven angles (see the header): (F_film(c) - f90 w) / (1 - w),
// w = (1 - c)^5, at its largest, and at least f0.
Rgb film_f0_bound(const Rgb& f0, float f90, float film_ior, float thickness_nm) {
  Rgb bound = f0;
  for (float c : {1.0f, 0.85f, 0.7f, 0.55f, 0.4f, 0.25f, 0.1f}) {
    const Rgb f = fresnel_thin_film(c, 1.0f, film_ior, thickness_nm, f0);
    const float w = sqr(sqr(1 - c)) * (1 - c);
    for (int i = 0; i < 3; ++i) bound[i] = std::max(bound[i], (f[i] - f90 * w) / (1 - w));
  }
  return vmin(bound, Rgb(1));
}

struct GltfLobes {
  Rgb base_color{1, 1, 1};
  float metallic = 1;
  float alpha = 1;
  Rgb f0_d{0.04f, 0.04f, 0.04f};
  float f90_d = 1;
  float transmission = 0;
  // The transmission lobe's tint: the base colour, or with subsurface its mix with the untinted interface into the
  // subsurface volume (whose colour is the medium's).
  Rgb transmission_color{1, 1, 1};
  float alpha_t = 1;   // the transmission lobe's
  bool solid = false;  // transmission through a dielectric volume (refracting), not a thin wall
  float eta = 1.5f;    // the volume's IOR, for solid transmission
  float clearcoat = 0;
  float alpha_c = 0.002f;
  Vec3 coat_n{0, 0, 1};  // the clearcoat's normal in the shading frame
  Rgb sheen_color{0, 0, 0};
  float alpha_sheen = 0.01f;
  float anisotropy = 0;                // KHR_materials_anisotropy's strength, in [0, 1]
  float aniso_cos = 1, aniso_sin = 0;  // its direction in the shading frame's tangent plane
  float diffuse_transmission = 0;      // KHR_materials_diffuse_transmission: the diffuse share transmitted
  Rgb diffuse_transmission_color{1, 1, 1};
  float iridescence = 0;            // KHR_materials_iridescence: the film's weight, in [0, 1]
  float iridescence_ior = 1.3f;     // the film's index
  float iridescence_thickness = 0;  // the film's thickness, nanometres
  // film_f0_bound of f0_d, f90_d and the film, when the material knows it for every point (negative: not known, the
  // BSDF works it out if it needs it).
  Rgb film_f0_bound{-1, -1, -1};
};

class GltfPbrBsdf final : public Bsdf {
 public:
  explicit GltfPbrBsdf(const GltfLobes& l) : l_(l) {
    dist_.type = MicrofacetType::kGgx;
    dist_.alpha_x = dist_.alpha_y = l.alpha;
    if (l.anisotropy > 0) {
      dist_.alpha_x = l.alpha + (1 - l.alpha) * sqr(l.anisotropy);  // alpha_t = mix(alpha, 1, strength^2)
      aniso_ = true;
    }
    dist_t_.type = MicrofacetType::kGgx;
    dist_t_.alpha_x = dist_t_.alpha_y = l.alpha_t;
    dist_c_.type = MicrofacetType::kGgx;
    dist_c_.alpha_x = dist_c_.alpha_y = l.alpha_c;
    coat_tilted_ = l.coat_n.z < 1;
    if (coat_tilted_) {
      const Vec3 c = to_aniso(l.coat_n);
      coat_frame_ = Frame::from_normal(c);
      // The back side (wo below): the mirrored configuration of the coat seen from behind, normal -c mirrored.
      coat_frame_back_ = Frame::from_normal(Vec3(-c.x, -c.y, c.z));
    }
    if (solid()) interface_ = RoughDielectric{dist_t_, l.eta, 1.0f, max_component(l.transmission_color)};
    f0_albedo_ = l.f0_d;
    if (l.iridescence > 0 && l.metallic < 1) {
      const Rgb bound = l.film_f0_bound.x >= 0
                            ? l.film_f0_bound
                            : film_f0_bound(l.f0_d, l.f90_d, l.iridescence_ior, l.iridescence_thickness);
      f0_albedo_ = lerp_rgb(l.f0_d, bound, l.iridescence);
    }
    float a1, a2;
    SchlickAlbedoTable::get().average(l.alpha, &a1, &a2);
    specular_average_ = std::min(max_component(f0_albedo_ * a1 + Rgb(l.f90_d * a2)), 0.999f);
    sheen_max_ = max_component(l.sheen_color);
    // The diffuse lobe's share that transmits, for sampling: by the luminances of the two colours.
    const float dr = (1 - l.diffuse_transmission) * luminance(l.base_color),
                dt = l.diffuse_transmission * luminance(l.diffuse_transmission_color);
    diffuse_t_share_ = dr + dt > 0 ? dt / (dr + dt) : 0;
  }

  Rgb eval(const Vec3& wo, const Vec3& wi) const override { return evaluate(to_aniso(wo), to_aniso(wi), nullptr); }
  Rgb eval_pdf(const Vec3& wo, const Vec3& wi, float* pdf_out) const override {
    return evaluate(to_aniso(wo), to_aniso(wi), pdf_out);
  }

  std::optional<BsdfSample> sample(const Vec3& wo, float uc, Vec2 u) const override {
    std::optional<BsdfSample> s = sample_local(to_aniso(wo), uc, u);
    if (s) s->wi = from_aniso(s->wi);
    return s;
  }

  float pdf(const Vec3& wo, const Vec3& wi) const override {
    float p;
    evaluate(to_aniso(wo), to_aniso(wi), &p);  // one formula for the pdf; pdf alone is not on the render loop's path
    return p;
  }

  // The adjoint (bsdf.h): solid transmission refracts, and its radiance form's 1/eta'^2 is taken out again.
  Rgb eval_adjoint(const Vec3& wo, const Vec3& wi) const override {
    const Rgb f = eval(wo, wi);
    return solid() && wo.z * wi.z < 0 ? f * sqr(wo.z > 0 ? l_.eta : 1 / l_.eta) : f;
  }
  std::optional<BsdfSample> sample_adjoint(const Vec3& wo, float uc, Vec2 u) const override {
    std::optional<BsdfSample> s = sample(wo, uc, u);
    if (s && (s->flags & kBsdfTransmission)) s->f *= sqr(s->eta);
    return s;
  }

  uint32_t flags() const override {
    uint32_t f = kBsdfReflection | kBsdfDiffuse | kBsdfGlossy;
    if ((l_.transmission > 0 || l_.diffuse_transmission > 0) && l_.metallic < 1) f |= kBsdfTransmission;
    return f;
  }
  Rgb albedo_hint() const override { return l_.base_color; }
  float roughness_hint() const override { return dist_.roughness(); }
  Rgb eval_diffuse(const Vec3& wo, const Vec3& wi) const override {
    Rgb d;
    evaluate(to_aniso(wo), to_aniso(wi), nullptr, &d);
    return d;
  }
  // Diffuse: the base colour under the metal and the transmission, with the diffuse transmission's colour; glossy:
  // the specular colour at normal incidence, the dielectric's F0 blended to the base colour by metallic (glTF 2.0
  // Appendix B); transmission: the base colour of the transmitting share.
  LobeColors lobe_colors() const override {
    const float m = l_.metallic;
    const Rgb diffuse = l_.base_color * ((1 - m) * (1 - l_.transmission) * (1 - l_.diffuse_transmission)) +
                        l_.diffuse_transmission_color * ((1 - m) * (1 - l_.transmission) * l_.diffuse_transmission);
    return {diffuse, lerp_rgb(f0_albedo_, l_.base_color, m), l_.transmission_color * ((1 - m) * l_.transmission)};
  }

 private:
  // The shading frame turned about the normal so that +x is the anisotropy direction, and back.
  Vec3 to_aniso(const Vec3& w) const {
    return aniso_ ? Vec3(l_.aniso_cos * w.x + l_.aniso_sin * w.y, l_.aniso_cos * w.y - l_.aniso_sin * w.x, w.z) : w;
  }
  Vec3 from_aniso(const Vec3& w) const {
    return aniso_ ? Vec3(l_.aniso_cos * w.x - l_.aniso_sin * w.y, l_.aniso_sin * w.x + l_.aniso_cos * w.y, w.z) : w;
  }

  // sample() in the anisotropy frame.
  std::optional<BsdfSample> sample_local(const Vec3& wo_in, float uc, Vec2 u) const {
    if (wo_in.z == 0) return std::nullopt;
    Vec3 wo = wo_in;
    const bool flip = wo.z < 0;
    if (flip) wo.z = -wo.z;
    const float* p = lobes_at(wo, flip);
    Vec3 wi;
    uint32_t flags;
    if (uc < p[0] || uc >= p[0] + p[1] + p[2] + p[3]) {  // diffuse or sheen: cosine-weighted
      wi = sample_cosine_hemisphere(u);
      flags = kBsdfReflection | (uc < p[0] ? kBsdfDiffuse : kBsdfGlossy);
      if (uc < p[0] * diffuse_t_share_) {  // the diffuse lobe's transmitted part
        wi.z = -wi.z;
        flags = kBsdfTransmission | kBsdfDiffuse;
      }
    } else if (uc < p[0] + p[1]) {
      if (!microfacet_reflection_sample(dist_, wo, u, 0.5f, &wi)) return std::nullopt;
      flags = kBsdfReflection | kBsdfGlossy;
    } else if (uc < p[0] + p[1] + p[2]) {
      if (solid()) {
        // The interface, in the unmirrored frame: refraction in from outside, out (or total reflection) from inside.
        bool transmitted;
        float etap;
        if (!interface_.sample(wo_in, (uc - p[0] - p[1]) / p[2], u, &wi, &transmitted, &etap)) return std::nullopt;
        float pdf_value;
        const Rgb f = evaluate(wo_in, wi, &pdf_value);
        if (!(pdf_value > 0)) return std::nullopt;
        return BsdfSample{f, wi, pdf_value, (transmitted ? kBsdfTransmission : kBsdfReflection) | kBsdfGlossy, etap};
      }
      if (!microfacet_reflection_sample(dist_t_, wo, u, 0.5f, &wi)) return std::nullopt;
      wi.z = -wi.z;
      flags = kBsdfTransmission | kBsdfGlossy;
    } else {
      const Frame& cf = coat_frame(flip);
      if (!microfacet_reflection_sample(dist_c_, to_coat(cf, wo), u, 0.5f, &wi)) return std::nullopt;
      wi = from_coat(cf, wi);
      if (wi.z <= 0) return std::nullopt;  // a coat direction under the base: not a reflection the model has
      flags = kBsdfReflection | kBsdfGlossy;
    }
    if (flip) wi.z = -wi.z;
    float pdf_value;
    Rgb f = evaluate(wo_in, wi, &pdf_value);
    if (!(pdf_value > 0)) return std::nullopt;
    return BsdfSample{f, wi, pdf_value, flags, 1.0f};
  }

  // f(wo, wi), and with `pdf_out` also the density with which `sample` picks wi: one pass shares the half vector,
  // D, Lambda and the lobe weights between the two.
  // `diffuse_out`, when given, receives the diffuse lobes' share of the value (Bsdf::eval_diffuse): the diffuse
  // reflection and the diffuse transmission, under the sheen and the coat as the rest.
  Rgb evaluate(const Vec3& wo_in, const Vec3& wi_in, float* pdf_out, Rgb* diffuse_out = nullptr) const {
    if (pdf_out) *pdf_out = 0;
    if (diffuse_out) *diffuse_out = Rgb(0);
    Rgb d(0);
    Vec3 wo = wo_in, wi = wi_in;
    if (wo.z == 0 || wi.z == 0) return Rgb(0);
    if (wo.z < 0) {
      wo.z = -wo.z;
      wi.z = -wi.z;
    }
    const bool transmit = wi.z < 0;
    if (transmit && l_.transmission <= 0 && l_.diffuse_transmission <= 0) return Rgb(0);
    const Vec3 wr(wi.x, wi.y, std::abs(wi.z));  // the mirrored pair for transmission
    const float m = l_.metallic;
    Rgb f(0);
    // Solid transmission: the dielectric interface, on the pair as given (its two sides differ).
    if (solid()) {
      bool transmitted;
      const float fi = interface_.eval(wo_in, wi_in, &transmitted);
      const float share = (1 - m) * l_.transmission;
      f = (transmitted ? l_.transmission_color : Rgb(1)) * (share * fi);
      if (pdf_out) *pdf_out = lobes_at(wo, wo_in.z < 0)[2] * interface_.pdf(wo_in, wi_in);
    }
    Vec3 h;
    float vh = 1;
    const bool thin_transmit = transmit && !solid();
    if ((!transmit || thin_transmit) && reflection_half_vector(wo, wr, &h)) {
      vh = dot(wo, h);
      float specular_pdf;
      const float dv = microfacet_reflection_eval_pdf(transmit ? dist_t_ : dist_, wo, wr, h, &specular_pdf);
      if (pdf_out) {
        const float* p = lobes_at(wo, wo_in.z < 0);
        if (transmit) {
          *pdf_out = p[2] * specular_pdf;
        } else {
          *pdf_out += (p[0] * (1 - diffuse_t_share_) + p[4]) * cosine_hemisphere_pdf(wr.z) + p[1] * specular_pdf;
          if (p[3] > 0) {
            const Frame& cf = coat_frame(wo_in.z < 0);
            *pdf_out += p[3] * microfacet_reflection_pdf(dist_c_, to_coat(cf, wo), to_coat(cf, wr));
          }
        }
      }
      Rgb fd = fresnel_schlick(l_.f0_d, Rgb(l_.f90_d), vh);
      if (l_.iridescence > 0) fd = lerp_rgb(fd, film_fresnel(l_.f0_d, vh), l_.iridescence);
      const float fd_max = max_component(fd);
      if (transmit) {
        f = l_.transmission_color * ((1 - m) * l_.transmission * (1 - fd_max) * dv);
      } else {
        lobes_at(wo, wo_in.z < 0);  // fills cache_.albedo_o
        const float w = (1 - cache_.albedo_o) * (1 - specular_albedo(wr.z)) / (1 - specular_average_);
        // With solid transmission the interface reflects for its share of the surface.
        const float specular_share = solid() ? (1 - m) * (1 - l_.transmission) : 1 - m;
        d = l_.base_color * ((1 - m) * (1 - l_.transmission) * (1 - l_.diffuse_transmission) * w * kInvPi);
        f += d + fd * (specular_share * dv);
        if (m > 0) {
          Rgb fm = fresnel_schlick(l_.base_color, Rgb(1), vh);
          if (l_.iridescence > 0) fm = lerp_rgb(fm, film_fresnel(l_.base_color, vh), l_.iridescence);
          f += fm * (m * dv);
        }
      }
    } else if (!solid()) {
      return Rgb(0);
    }
    if (transmit && l_.diffuse_transmission > 0) {
      // The Lambertian BTDF, coupled to the specular lobe by the albedos of wo and the mirrored wi, as the diffuse
      // reflection is.
      const float* p = lobes_at(wo, wo_in.z < 0);
      const float w = (1 - cache_.albedo_o) * (1 - specular_albedo(wr.z)) / (1 - specular_average_);
      const Rgb dt =
          l_.diffuse_transmission_color * ((1 - m) * (1 - l_.transmission) * l_.diffuse_transmission * w * kInvPi);
      f += dt;
      d += dt;
      if (pdf_out) *pdf_out += p[0] * diffuse_t_share_ * cosine_hemisphere_pdf(wr.z);
    }
    if (sheen_max_ > 0) {
      const float eo = sheen_albedo(wo.z), ei = sheen_albedo(wr.z);
      const float below = std::min(1 - sheen_max_ * std::min(eo, 1.0f), 1 - sheen_max_ * std::min(ei, 1.0f));
      f = f * below;
      d = d * below;
      // The Charlie lobe's albedo exceeds 1 near grazing angles; dividing by max(1, E_sh(mu_o), E_sh(mu_i)) bounds
      // it by 1 and stays symmetric.
      if (!transmit) f += l_.sheen_color * (sheen_eval(wo, wr, l_.alpha_sheen) / std::max(1.0f, std::max(eo, ei)));
    }
    if (l_.clearcoat > 0) {
      const Frame& cf = coat_frame(wo_in.z < 0);
      const Vec3 wo_c = to_coat(cf, wo), wr_c = to_coat(cf, wr);
      const float below = std::min(1 - l_.clearcoat * coat_albedo(wo_c.z), 1 - l_.clearcoat * coat_albedo(wr_c.z));
      f = f * below;
      d = d * below;
      if (!transmit) {
        // V.H: the half vector of the pair is the same in either frame.
        Vec3 hc;
        const float fc = reflection_half_vector(wo, wr, &hc) ? l_.clearcoat * fresnel_schlick(0.04f, dot(wo, hc)) : 0;
        f += Rgb(fc * microfacet_reflection_eval(dist_c_, wo_c, wr_c));
      }
    }
    if (diffuse_out) *diffuse_out = d;
    return f;
  }

  // The lobe probabilities and the specular albedo at wo (upper side), kept for the wo of the last call: a path
  // vertex asks for them up to three times (light sample, BSDF sample, its evaluation) with the same wo.
  // `back`: wo was mirrored from the back side (the coat's own normal then differs).
  const float* lobes_at(const Vec3& wo, bool back) const {
    if (!(wo.x == cache_.wo.x && wo.y == cache_.wo.y && wo.z == cache_.wo.z && back == cache_.back)) {
      lobe_probabilities(wo, back, cache_.p);
      cache_.albedo_o = specular_albedo(wo.z);
      cache_.wo = wo;
      cache_.back = back;
    }
    return cache_.p;
  }

  // Probabilities of the diffuse, specular, transmission, clearcoat and sheen lobes, from their weights at wo with
  // the Fresnel terms taken at the normal (Schlick at N.V).
  void lobe_probabilities(const Vec3& wo, bool back, float p[5]) const {
    const float m = l_.metallic;
    const Rgb fd = fresnel_schlick(l_.f0_d, Rgb(l_.f90_d), wo.z);
    const float fd_max = max_component(fd);
    const float base = luminance(l_.base_color);
    // The coat's weight from the cosine about its own normal; none where wo is under the coat.
    const float coat_cos = to_coat(coat_frame(back), wo).z;
    const float fc = coat_cos > 0 ? l_.clearcoat * fresnel_schlick(0.04f, coat_cos) : 0;
    const float diffuse =
        (1 - l_.diffuse_transmission) * base + l_.diffuse_transmission * luminance(l_.diffuse_transmission_color);
    p[0] = (1 - fc) * (1 - m) * (1 - l_.transmission) * (1 - fd_max) * diffuse;
    const float t = l_.transmission;
    if (solid()) {
      // The interface reflects and transmits: its share of the surface, by what it reflects and what it passes.
      p[1] =
          (1 - fc) * ((1 - m) * (1 - t) * luminance(fd) + m * luminance(fresnel_schlick(l_.base_color, Rgb(1), wo.z)));
      p[2] = (1 - fc) * (1 - m) * t * (fd_max + (1 - fd_max) * luminance(l_.transmission_color));
    } else {
      p[1] = (1 - fc) * ((1 - m) * luminance(fd) + m * luminance(fresnel_schlick(l_.base_color, Rgb(1), wo.z)));
      p[2] = (1 - fc) * (1 - m) * t * (1 - fd_max) * luminance(l_.transmission_color);
    }
    p[3] = fc;
    p[4] = 0;
    if (sheen_max_ > 0) {
      const float es = sheen_max_ * std::min(sheen_albedo(wo.z), 1.0f);
      for (int i = 0; i < 3; ++i) p[i] *= 1 - es;
      p[4] = (1 - fc) * es;
    }
    float sum = p[0] + p[1] + p[2] + p[3] + p[4];
    if (!(sum > 0)) {
      p[0] = 0;
      p[1] = 1;
      p[2] = p[3] = p[4] = 0;
      return;
    }
    for (int i = 0; i < 5; ++i) p[i] /= sum;
  }

  // The dielectric specular lobe's albedo E_s(mu) (its largest channel; of f0_albedo_, the film's bound mixed in) and
  // the clearcoat's.
  float specular_albedo(float mu) const {
    float e1, e2;
    SchlickAlbedoTable::get().eval(mu, l_.alpha, &e1, &e2);
    return std::min(max_component(f0_albedo_ * e1 + Rgb(l_.f90_d * e2)), 0.999f);
  }
  float sheen_albedo(float mu) const { return SheenAlbedoTable::get().eval(mu, l_.alpha_sheen); }
  float coat_albedo(float mu) const {
    float e1, e2;
    SchlickAlbedoTable::get().eval(mu, l_.alpha_c, &e1, &e2);
    return std::min(0.04f * e1 + e2, 1.0f);
  }

  bool solid() const { return l_.solid && l_.transmission > 0 && l_.metallic < 1; }
  // The clearcoat's frame in the (mirrored-to-front) shading frame, for wo on the front or (`back`) the back side.
  const Frame& coat_frame(bool back) const { return back ? coat_frame_back_ : coat_frame_; }
  Vec3 to_coat(const Frame& cf, const Vec3& w) const { return coat_tilted_ ? cf.to_local(w) : w; }
  Vec3 from_coat(const Frame& cf, const Vec3& w) const { return coat_tilted_ ? cf.to_world(w) : w; }

  GltfLobes l_;
  MicrofacetDistribution dist_, dist_t_, dist_c_;
  RoughDielectric interface_;  // solid transmission's
  bool coat_tilted_ = false;   // the coat has its own normal
  bool aniso_ = false;         // KHR_materials_anisotropy: dist_ is anisotropic along the frame's +x
  Frame coat_frame_, coat_frame_back_;
  // A BSDF belongs to one path vertex on one thread, so the cache needs no synchronisation. wo starts as a direction
  // no caller passes (not unit length).
  mutable struct {
    Vec3 wo{0, 0, 0};
    float p[5] = {0, 0, 0, 0, 0};
    float albedo_o = 0;
    bool back = false;
  } cache_;
  float specular_average_ = 0;
  Rgb f0_albedo_;  // the f0 of the specular lobe's albedo for the diffuse coupling: f0_d, or with a film its bound
  float sheen_max_ = 0;
  float diffuse_t_share_ = 0;  // of the diffuse lobe's samples, the transmitted ones

  static Rgb lerp_rgb(const Rgb& a, const Rgb& b, float t) { return a * (1 - t) + b * t; }
  // KHR_materials_iridescence's Fresnel of a base of normal-incidence reflectance f0 under the film, in air.
  Rgb film_fresnel(const Rgb& f0, float cos_theta) const {
    return fresnel_thin_film(cos_theta, 1.0f, l_.iridescence_ior, l_.iridescence_thickness, f0);
  }
};

// The parameters of a gltf_pbr, as its factory reads them.
struct GltfPbrParams {
  RgbParam base_color, specular_color, sheen_color;
  FloatParam metallic, roughness, specular, transmission, clearcoat, clearcoat_roughness, sheen_roughness;
  FloatParam anisotropy;            // KHR_materials_anisotropy: anisotropyStrength (times the texture's B)
  RgbParam anisotropy_direction;    // its texture's RG: the direction in tangent space, mapped to [-1, 1]
  FloatParam diffuse_transmission;  // KHR_materials_diffuse_transmission: diffuseTransmissionFactor (times texture A)
  RgbParam diffuse_transmission_color;
  FloatParam iridescence;            // KHR_materials_iridescence: iridescenceFactor (times the texture's R)
  FloatParam iridescence_thickness;  // its thickness texture's G: where between minimum and maximum
  float iridescence_ior = 1.3f, iridescence_thickness_min = 100, iridescence_thickness_max = 400;
  float aniso_rot_cos = 1, aniso_rot_sin = 0;  // anisotropyRotation, counter-clockwise from the tangent
  float f0_ior = 0.04f;
  float transmission_roughness_scale = 1;  // clamp(2 ior - 2, 0, 1)
  float ior = 1.5f;
  bool solid = false;           // "thin_walled": false, and an index that refracts
  float subsurface_weight = 0;  // a solid's share of the dielectric base that is its subsurface volume (interior)
  float dispersion = 0;         // KHR_materials_dispersion: 20 / V_d, a solid's only (Material::Traits::dispersive)
  // The film's f0 bound (film_f0_bound), worked out once where nothing it depends on varies over the surface.
  Rgb film_bound{-1, -1, -1};
  // metallic's and roughness's textures as one RGB lookup, when they read channels of the same image.
  std::shared_ptr<const Texture> metallic_roughness;
  int metallic_channel = 0, roughness_channel = 0;

  // The dielectric's f0 at sp (KHR_materials_specular: specular_color tints, specular scales) for the normal-incidence
  // reflectance f0 of its index, and its f90.
  Rgb dielectric_f0(float f0, const ShadingPoint& sp, float* f90) const {
    const float spec = clamp(specular.eval(sp), 0.0f, 1.0f);
    *f90 = spec;
    return vmin(Rgb(f0) * specular_color.eval(sp), Rgb(1)) * spec;
  }
  // The iridescent film's thickness at sp, nanometres: between the minimum and the maximum by the texture.
  float film_thickness(const ShadingPoint& sp) const {
    const float t = clamp(iridescence_thickness.eval(sp), 0.0f, 1.0f);
    return iridescence_thickness_min + (iridescence_thickness_max - iridescence_thickness_min) * t;
  }
};

// The material reads its parameters as members of its own (a private base).
class GltfPbrMaterial final : public Material, private GltfPbrParams {
 public:
  GltfPbrMaterial(GltfPbrParams params, Traits traits, std::shared_ptr<const Medium> interior)
      : Material(traits, Common{.interior = std::move(interior)}), GltfPbrParams(std::move(params)) {}

  const Bsdf* bsdf(const ShadingPoint& sp, ScratchArena& arena) const override {
    GltfLobes l;
    l.base_color = vmin(base_color.eval(sp) * sp.vertex_color, Rgb(1));
    float metal, rough;
    if (metallic_roughness) {
      // One lookup for both (glTF keeps them in the B and G channels of one image).
      const Rgb t = metallic_roughness->eval(sp);
      metal = metallic.value * t[metallic_channel];
      rough = roughness.value * t[roughness_channel];
    } else {
      metal = metallic.eval(sp);
      rough = roughness.eval(sp);
    }
    l.metallic = clamp(metal, 0.0f, 1.0f);
    float r = clamp(rough, 0.002f, 1.0f);
    l.alpha = r * r;
    const float rt = clamp(r * transmission_roughness_scale, 0.002f, 1.0f);
    l.alpha_t = rt * rt;
    // A dispersive solid refracts, and reflects, by its index at the path's wavelength (spectrum.h).
    float eta = ior, f0 = f0_ior;
    if (dispersive() && sp.wavelength_nm > 0) {
      eta = std::max(spectrum::dispersive_ior(ior, dispersion, sp.wavelength_nm), 1.001f);
      f0 = f0_from_ior(eta);
    }
    l.f0_d = dielectric_f0(f0, sp, &l.f90_d);
    l.transmission = clamp(transmission.eval(sp), 0.0f, 1.0f);
    l.transmission_color = l.base_color;
    if (subsurface_weight > 0) {
      // OpenPBR's dielectric base: mix(mix(diffuse, subsurface, subsurface_weight), translucent, transmission). The
      // subsurface share refracts through the same interface into the material's interior medium, untinted.
      const float t = l.transmission, w = (1 - t) * subsurface_weight;
      l.transmission = t + w;
      l.transmission_color = (l.base_color * t + Rgb(w)) / l.transmission;
    }
    l.solid = solid;
    l.eta = eta;
    l.clearcoat = clamp(clearcoat.eval(sp), 0.0f, 1.0f);
    float rc = clamp(clearcoat_roughness.eval(sp), 0.002f, 1.0f);
    l.alpha_c = rc * rc;
    if (l.clearcoat > 0 && length_squared(sp.coat_normal) > 0) l.coat_n = normalize(sp.frame.to_local(sp.coat_normal));
    l.sheen_color = vmin(vmax(sheen_color.eval(sp), Rgb(0)), Rgb(1));
    float rs = clamp(sheen_roughness.eval(sp), 0.0f, 1.0f);
    l.alpha_sheen = std::max(rs * rs, SheenAlbedoTable::kMinAlpha);
    // Thin-walled only: a solid's transmission is its refracting interface.
    l.diffuse_transmission = solid ? 0.0f : clamp(diffuse_transmission.eval(sp), 0.0f, 1.0f);
    if (l.diffuse_transmission > 0)
      l.diffuse_transmission_color = vmin(vmax(diffuse_transmission_color.eval(sp), Rgb(0)), Rgb(1));
    l.iridescence = clamp(iridescence.eval(sp), 0.0f, 1.0f);
    if (l.iridescence > 0) {
      l.iridescence_ior = iridescence_ior;
      l.iridescence_thickness = film_thickness(sp);
      l.film_f0_bound = film_bound;
    }
    l.anisotropy = clamp(anisotropy.eval(sp), 0.0f, 1.0f);
    if (l.anisotropy > 0) {
      // KHR_materials_anisotropy: direction = rotation(anisotropyRotation) * (texture.rg * 2 - 1), in the tangent
      // frame (tangent, bitangent = sign * n x t); tessera's frame has t = n x s, hence the sign on y.
      float dx = 1, dy = 0;
      if (anisotropy_direction.texture) {
        const Rgb d = anisotropy_direction.eval(sp);
        dx = 2 * d[0] - 1;
        dy = 2 * d[1] - 1;
      }
      const float rx = aniso_rot_cos * dx - aniso_rot_sin * dy,
                  ry = (aniso_rot_sin * dx + aniso_rot_cos * dy) * sp.tangent_sign;
      const float len = std::sqrt(rx * rx + ry * ry);
      if (len > 0) {
        l.aniso_cos = rx / len;
        l.aniso_sin = ry / len;
      } else {
        l.anisotropy = 0;
      }
    }
    return arena.make<GltfPbrBsdf>(l);
  }
};

// The subsurface lobe of a gltf_pbr with subsurface_weight above 0: a solid's interior becomes the subsurface medium
// (subsurface.h, returned), entered through the transmission lobe's interface. A thin-walled surface has no interior
// (null): its subsurface falls back to diffuse transmission of subsurface_color (as glTF's
// KHR_materials_volume_scatter does without KHR_materials_volume).
std::shared_ptr<const Medium> read_subsurface_lobe(const nlohmann::json& j, const std::string& ptr,
                                                   const SubsurfaceParams& sss, bool thin_walled, GltfPbrParams& m) {
  if (thin_walled) {
    if (j.contains("diffuse_transmission") || j.contains("diffuse_transmission_color"))
      throw SceneError(ptr + "/subsurface_weight",
                       "a thin-walled surface's subsurface is diffuse transmission of subsurface_color: give "
                       "diffuse_transmission or subsurface_weight, not both");
    m.diffuse_transmission.value = sss.weight;
    m.diffuse_transmission_color.value = sss.color;
    return nullptr;
  }
  if (!m.solid)
    throw SceneError(ptr + "/ior",
                     "subsurface on a solid gltf_pbr is entered by refraction and needs an ior above 1.001; the "
                     "subsurface material has an index-matched boundary (ior 1)");
  m.subsurface_weight = sss.weight;
  return subsurface_medium(sss);
}

}  // namespace

void register_gltf_pbr(MaterialRegistry& registry) {
  registry.add("gltf_pbr", [](const nlohmann::json& j, const std::string& ptr, const MaterialContext& ctx) {
    GltfPbrParams p;
    p.base_color = params::rgb_param(j, "base_color", ptr, Rgb(1), 0.0f, 1.0f, ctx);
    p.metallic = params::float_param(j, "metallic", ptr, 1.0f, 0.0f, 1.0f, ctx);
    p.roughness = params::float_param(j, "roughness", ptr, 1.0f, 0.0f, 1.0f, ctx);
    if (p.metallic.texture && p.roughness.texture)
      p.metallic_roughness = make_shared_channels_texture(p.metallic.texture.get(), p.roughness.texture.get(),
                                                          &p.metallic_channel, &p.roughness_channel);
    float ior = params::number(j, "ior", ptr, 1.5f, 1.0f, 4.0f);
    p.f0_ior = f0_from_ior(ior);
    p.transmission_roughness_scale = clamp(2 * ior - 2, 0.0f, 1.0f);
    p.ior = ior;
    // An index within 0.1 % of 1 bends rays by less than a few hundredths of a degree and makes the refraction half
    // vector (Walter 2007, eq. 16) degenerate: such a volume is drawn thin-walled.
    // Subsurface makes a solid unless the surface is said to be thin-walled.
    const SubsurfaceParams sss = read_subsurface(j, ptr, true);
    const bool thin_walled = params::boolean(j, "thin_walled", ptr, !(sss.weight > 0));
    p.solid = !thin_walled && ior > 1.001f;
    // Dispersion parts the colours of light refracted through a solid; a thin wall lets light out as it came in.
    p.dispersion = params::number(j, "dispersion", ptr, 0.0f, 0.0f, 100.0f);
    const bool dispersive = p.solid && p.dispersion > 0;
    p.specular = params::float_param(j, "specular", ptr, 1.0f, 0.0f, 1.0f, ctx);
    p.specular_color = params::rgb_param(j, "specular_color", ptr, Rgb(1), 0.0f, 1e3f, ctx);
    p.transmission = params::float_param(j, "transmission", ptr, 0.0f, 0.0f, 1.0f, ctx);
    p.clearcoat = params::float_param(j, "clearcoat", ptr, 0.0f, 0.0f, 1.0f, ctx);
    p.clearcoat_roughness = params::float_param(j, "clearcoat_roughness", ptr, 0.0f, 0.0f, 1.0f, ctx);
    p.sheen_color = params::rgb_param(j, "sheen_color", ptr, Rgb(0), 0.0f, 1.0f, ctx);
    p.sheen_roughness = params::float_param(j, "sheen_roughness", ptr, 0.0f, 0.0f, 1.0f, ctx);
    p.diffuse_transmission = params::float_param(j, "diffuse_transmission", ptr, 0.0f, 0.0f, 1.0f, ctx);
    p.diffuse_transmission_color = params::rgb_param(j, "diffuse_transmission_color", ptr, Rgb(1), 0.0f, 1.0f, ctx);
    std::shared_ptr<const Medium> interior;
    if (sss.weight > 0) interior = read_subsurface_lobe(j, ptr, sss, thin_walled, p);
    p.iridescence = params::float_param(j, "iridescence", ptr, 0.0f, 0.0f, 1.0f, ctx);
    p.iridescence_ior = params::number(j, "iridescence_ior", ptr, 1.3f, 1.0f, 4.0f);
    p.iridescence_thickness = params::float_param(j, "iridescence_thickness", ptr, 1.0f, 0.0f, 1.0f, ctx);
    p.iridescence_thickness_min = params::number(j, "iridescence_thickness_minimum", ptr, 100.0f, 0.0f, 1e4f);
    p.iridescence_thickness_max = params::number(j, "iridescence_thickness_maximum", ptr, 400.0f, 0.0f, 1e4f);
    p.anisotropy = params::float_param(j, "anisotropy", ptr, 0.0f, 0.0f, 1.0f, ctx);
    p.anisotropy_direction = params::rgb_param(j, "anisotropy_direction", ptr, Rgb(1, 0.5f, 1), 0.0f, 1.0f, ctx);
    const float rotation = params::number(j, "anisotropy_rotation", ptr, 0.0f, -1e3f, 1e3f);
    p.aniso_rot_cos = std::cos(rotation);
    p.aniso_rot_sin = std::sin(rotation);
    // A film of one thickness on a base of one f0: its bound once here rather than at every hit (7 film Fresnels).
    if ((p.iridescence.texture || p.iridescence.value > 0) && !p.iridescence_thickness.texture && !p.specular.texture &&
        !p.specular_color.texture && !dispersive) {
      const ShadingPoint anywhere;  // the parameters are untextured: any point gives them
      float f90;
      const Rgb f0 = p.dielectric_f0(p.f0_ior, anywhere, &f90);
      p.film_bound = film_f0_bound(f0, f90, p.iridescence_ior, p.film_thickness(anywhere));
    }
    // An anisotropic lobe needs the hit's tangent (so does a normal map, which the hits see for themselves).
    const bool isotropic = !p.anisotropy.texture && !(p.anisotropy.value > 0);
    // The albedo tables are computed once per process (0.1 s, and 0.2 s for sheen's): here, while the scene loads,
    // rather than on a render thread in the first pass, where the other render threads would wait for them.
    SchlickAlbedoTable::get();
    if (p.sheen_color.texture || !is_black(p.sheen_color.value)) SheenAlbedoTable::get();
    return std::make_unique<GltfPbrMaterial>(
        std::move(p), Material::Traits{.isotropic = isotropic, .dispersive = dispersive}, std::move(interior));
  });
}

}  // namespace tessera
