// Cameras: map a point on the film (continuous pixel coordinates) and a lens sample to a primary ray.
#pragma once

#include <vector>

#include "renderer/math.h"

namespace tessera {

// The camera as a sensor for paths traced from the lights: what a point or a ray is worth to the image.
struct CameraImportanceSample {
  float importance = 0;  // W_e of the ray from the lens point towards the reference point
  Vec3 wi;               // unit direction from the reference point towards the lens point
  float dist = 0;        // distance between them
  float pdf = 0;         // solid-angle density of wi at the reference point
  Vec3 p_lens;           // the lens point (the camera position for a pinhole)
  Vec2 film;             // the pixel position the ray lands on
};

struct CameraDesc {
  enum class Projection { kPerspective, kOrthographic };
  Projection projection = Projection::kPerspective;
  Vec3 from{0, 0, 5};
  Vec3 to{0, 0, 0};
  Vec3 up{0, 1, 0};
  float fov_deg = 40;         // vertical field of view (perspective)
  float ortho_height = 2;     // vertical extent of the view in scene units (orthographic)
  float aperture_radius = 0;  // thin lens radius; 0 is a pinhole
  float focus_distance = 0;   // 0: the distance from `from` to `to`
};

// A moving camera at ray time `time` in [0, 1]: its poses at evenly spaced time steps (0 at the first, 1 at the last),
// interpolated linearly between the two around `time` (position, target, up, field of view, lens), as the geometry's
// time steps are. `steps` must hold at least two.
CameraDesc camera_at(const std::vector<CameraDesc>& steps, float time);

class Camera {
 public:
  Camera() = default;
  Camera(const CameraDesc& desc, int width, int height);
  // `film` in pixels: (0,0) is the top-left corner of the image, (width,height) the bottom-right.
  Ray generate_ray(Vec2 film, Vec2 u_lens) const;
  // The cone of one of `samples_per_pixel` rays of a pixel: a pinhole's start at a point and widen by one pixel's
  // angle (at the image centre) per unit of distance, an orthographic camera's are a pixel wide and do not widen
  // (Akenine-Möller et al. 2019), each narrowed by 1 / sqrt(samples_per_pixel). The pixel's box filter already averages
  // its samples over the pixel, so each sample stands for its 1/N share of the pixel's area, a patch 1/sqrt(N) of its
  // width (the stratum of a stratified sampler); a whole pixel's footprint per sample would blur twice. Narrowed at
  // most 16x (256 samples): finer than that the finest mip level is read anyway. (A thin lens's rays are treated as a
  // pinhole's: the cone is for texture filtering, not depth of field.)
  RayCone pixel_cone(uint32_t samples_per_pixel = 1) const;
  // Pixel position where the world point `p` projects (for tests); false if behind the camera.
  bool project(const Vec3& p, Vec2* film) const;
  const CameraDesc& desc() const { return desc_; }

  // The adjoint of generate_ray (Veach 1997, 4.5 and 8.1.2; pbrt-v4, 5.4.1): the importance W_e of a perspective
  // camera, normalised so that the integral of W_e |cos| over the lens and the directions through the whole image is
  // 1. A pixel's own importance is width x height times W_e over the rays landing in it: the path tracer's average
  // over rays spread uniformly over a pixel estimates that measurement. With A the image plane's area at unit
  // distance and A_lens the lens area (1 for a pinhole), W_e = 1 / (A A_lens cos^4 theta) for rays whose direction,
  // at angle theta to the view axis, lands inside the image; 0 otherwise. Only perspective cameras have one
  // (has_importance); `film`, when given, receives the pixel position the ray lands on.
  bool has_importance() const { return desc_.projection == CameraDesc::Projection::kPerspective; }
  float importance(const Ray& ray, Vec2* film = nullptr) const;
  // The densities with which generate_ray, over a uniform film position on the whole image and a uniform lens
  // sample, makes `ray`: by area on the lens (1 for a pinhole) and by solid angle for its direction, 1 / (A cos^3).
  void importance_pdf(const Ray& ray, float* pdf_pos, float* pdf_dir) const;
  // Samples a point on the lens as seen from `ref` (u_lens as generate_ray reads it), for connecting a point to the
  // camera; false when the lens point cannot see ref's side of the camera or the ray misses the image.
  bool sample_importance(const Vec3& ref, Vec2 u_lens, CameraImportanceSample* out) const;
  // The view axis (the lens's normal).
  Vec3 forward() const { return frame_.n; }
  float lens_area() const { return uses_lens() ? kPi * sqr(desc_.aperture_radius) : 1.0f; }
  // Whether generate_ray reads u_lens (a thin lens); a pinhole or orthographic camera ignores it.
  bool uses_lens() const {
    return desc_.projection == CameraDesc::Projection::kPerspective && desc_.aperture_radius > 0;
  }

 private:
  CameraDesc desc_;
  int width_ = 1, height_ = 1;
  Frame frame_;       // s = right, t = up, n = forward
  float half_h_ = 1;  // tan(fov/2) or ortho half height
  float half_w_ = 1;
  float x_scale_ = 1, y_scale_ = 1;  // screen units per pixel: 2 half_w / width, 2 half_h / height
  float focus_ = 1;
  float image_area_ = 4;  // of the image plane at unit distance: 4 half_w half_h
};

}  // namespace tessera
