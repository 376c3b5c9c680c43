#include "renderer/camera.h"

#include <algorithm>

#include "renderer/sampling.h"

namespace tessera {

CameraDesc camera_at(const std::vector<CameraDesc>& steps, float time) {
  const float f = std::clamp(time, 0.0f, 1.0f) * static_cast<float>(steps.size() - 1);
  const size_t i = std::min(static_cast<size_t>(f), steps.size() - 2);
  const float u = f - static_cast<float>(i);
  const CameraDesc &a = steps[i], &b = steps[i + 1];
  auto mix = [u](auto x, auto y) { return x * (1 - u) + y * u; };
  CameraDesc c = a;
  c.from = mix(a.from, b.from);
  c.to = mix(a.to, b.to);
  c.up = mix(a.up, b.up);
  c.fov_deg = mix(a.fov_deg, b.fov_deg);
  c.ortho_height = mix(a.ortho_height, b.ortho_height);
  c.aperture_radius = mix(a.aperture_radius, b.aperture_radius);
  c.focus_distance = mix(a.focus_distance, b.focus_distance);
  return c;
}

Camera::Camera(const CameraDesc& desc, int width, int height) : desc_(desc), width_(width), height_(height) {
  Vec3 forward = normalize(desc.to - desc.from);
  Vec3 right = cross(forward, desc.up);
  if (length_squared(right) < 1e-12f)
    right = cross(forward, std::abs(forward.y) < 0.9f ? Vec3(0, 1, 0) : Vec3(1, 0, 0));
  right = normalize(right);
  Vec3 up = cross(right, forward);
  frame_ = Frame(right, up, forward);
  float aspect = static_cast<float>(width) / static_cast<float>(height);
  if (desc.projection == CameraDesc::Projection::kPerspective) {
    half_h_ = std::tan(desc.fov_deg * kPi / 360.0f);
  } else {
    half_h_ = desc.ortho_height * 0.5f;
  }
  half_w_ = half_h_ * aspect;
  x_scale_ = 2 * half_w_ / static_cast<float>(width);
  y_scale_ = 2 * half_h_ / static_cast<float>(height);
  focus_ = desc.focus_distance > 0 ? desc.focus_distance : length(desc.to - desc.from);
  image_area_ = 4 * half_w_ * half_h_;
}

Ray Camera::generate_ray(Vec2 film, Vec2 u_lens) const {
  // Screen coordinates in [-half_w, half_w] x [-half_h, half_h], y up: a multiply-add each (no division per ray).
  const float sx = film.x * x_scale_ - half_w_;
  const float sy = half_h_ - film.y * y_scale_;
  Ray ray;
  if (desc_.projection == CameraDesc::Projection::kOrthographic) {
    ray.origin = desc_.from + frame_.s * sx + frame_.t * sy;
    ray.dir = frame_.n;
    return ray;
  }
  Vec3 dir_local(sx, sy, 1);
  if (desc_.aperture_radius > 0) {
    // Thin lens: every ray through the lens point reaches the same point on the plane of focus.
    Vec3 focus_point = dir_local * focus_;
    Vec2 lens = sample_concentric_disk(u_lens) * desc_.aperture_radius;
    Vec3 lens_local(lens.x, lens.y, 0);
    ray.origin = desc_.from + frame_.to_world(lens_local);
    ray.dir = normalize(frame_.to_world(focus_point - lens_local));
  } else {
    ray.origin = desc_.from;
    ray.dir = normalize(frame_.to_world(dir_local));
  }
  return ray;
}

RayCone Camera::pixel_cone(uint32_t samples_per_pixel) const {
  const float share = 1 / std::sqrt(static_cast<float>(std::clamp<uint32_t>(samples_per_pixel, 1, 256)));
  const float pixel = 2 * half_h_ / static_cast<float>(height_) * share;
  if (desc_.projection == CameraDesc::Projection::kOrthographic) return {pixel, 0};
  return {0, pixel};
}

bool Camera::project(const Vec3& p, Vec2* film) const {
  Vec3 local = frame_.to_local(p - desc_.from);
  float sx, sy;
  if (desc_.projection == CameraDesc::Projection::kOrthographic) {
    sx = local.x;
    sy = local.y;
  } else {
    if (local.z <= 0) return false;
    sx = local.x / local.z;
    sy = local.y / local.z;
  }
  film->x = (sx / half_w_ + 1) * 0.5f * static_cast<float>(width_);
  film->y = (1 - sy / half_h_) * 0.5f * static_cast<float>(height_);
  return true;
}

float Camera::importance(const Ray& ray, Vec2* film) const {
  if (!has_importance()) return 0;
  const Vec3 d = frame_.to_local(ray.dir);
  const float len = length(d);
  if (!(len > 0)) return 0;
  const float cos_theta = d.z / len;
  if (cos_theta <= 0) return 0;
  // Where the ray crosses the plane of focus (a thin lens) or the unit plane (a pinhole), seen from the centre of
  // the lens: the film position a ray through the lens centre to that point has.
  const float plane = uses_lens() ? focus_ : 1.0f;
  const Vec3 o = frame_.to_local(ray.origin - desc_.from);
  const Vec3 p = o + d * ((plane - o.z) / d.z);
  const float sx = p.x / p.z, sy = p.y / p.z;
  if (sx < -half_w_ || sx > half_w_ || sy < -half_h_ || sy > half_h_) return 0;
  if (film) *film = Vec2((sx + half_w_) / x_scale_, (half_h_ - sy) / y_scale_);
  const float cos2 = cos_theta * cos_theta;
  return 1 / (image_area_ * lens_area() * cos2 * cos2);
}

void Camera::importance_pdf(const Ray& ray, float* pdf_pos, float* pdf_dir) const {
  *pdf_pos = *pdf_dir = 0;
  if (importance(ray) == 0) return;
  const float cos_theta = dot(normalize(ray.dir), frame_.n);
  *pdf_pos = 1 / lens_area();
  *pdf_dir = 1 / (image_area_ * cos_theta * cos_theta * cos_theta);
}

bool Camera::sample_importance(const Vec3& ref, Vec2 u_lens, CameraImportanceSample* out) const {
  if (!has_importance()) return false;
  Vec3 p_lens = desc_.from;
  if (uses_lens()) {
    const Vec2 lens = sample_concentric_disk(u_lens) * desc_.aperture_radius;
    p_lens = desc_.from + frame_.to_world(Vec3(lens.x, lens.y, 0));
  }
  const Vec3 d = p_lens - ref;
  const float dist2 = length_squared(d);
  if (!(dist2 > 0)) return false;
  const float dist = std::sqrt(dist2);
  const Vec3 wi = d / dist;
  const float cos_lens = std::abs(dot(wi, frame_.n));
  if (!(cos_lens > 0)) return false;
  Ray ray;
  ray.origin = p_lens;
  ray.dir = -wi;
  Vec2 film;
  const float we = importance(ray, &film);
  if (we == 0) return false;
  out->importance = we;
  out->wi = wi;
  out->dist = dist;
  // The lens point is uniform by area (a pinhole's point counts as an area of 1): to solid angle at ref.
  out->pdf = dist2 / (cos_lens * lens_area());
  out->p_lens = p_lens;
  out->film = film;
  return true;
}

}  // namespace tessera
