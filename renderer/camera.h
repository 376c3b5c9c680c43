// Cameras: map a point on the film (continuous pixel coordinates) and a lens sample to a primary ray.
#pragma once

#include "renderer/math.h"

namespace tessera {

struct CameraDesc {
  enum class Projection { kPerspective, kOrthographic };
  Projection projection = Projection::kPerspective;
  Vec3 from{0, 0, 5};
  Vec3 to{0, 0, 0};
  Vec3 up{0, 1, 0};
  float fov_deg = 40;        // vertical field of view (perspective)
  float ortho_height = 2;    // vertical extent of the view in scene units (orthographic)
  float aperture_radius = 0; // thin lens radius; 0 is a pinhole
  float focus_distance = 0;  // 0: the distance from `from` to `to`
};

class Camera {
 public:
  Camera() = default;
  Camera(const CameraDesc& desc, int width, int height);
  // `film` in pixels: (0,0) is the top-left corner of the image, (width,height) the bottom-right.
  Ray generate_ray(Vec2 film, Vec2 u_lens) const;
  // The cone of a pixel's rays: a pinhole's start at a point and widen by one pixel's angle (at the image centre) per
  // unit of distance; an orthographic camera's are a pixel wide and do not widen. (A thin lens's are treated as a
  // pinhole's: the cone is for texture filtering, not depth of field.)
  RayCone pixel_cone() const;
  // Pixel position where the world point `p` projects (for tests); false if behind the camera.
  bool project(const Vec3& p, Vec2* film) const;
  const CameraDesc& desc() const { return desc_; }
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
};

}  // namespace tessera
