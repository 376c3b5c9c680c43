// Material parameters: a constant, or a texture evaluated at the shading point.
#pragma once

#include <memory>

#include "renderer/math.h"

namespace tessera {

// What a material sees of the surface it shades.
struct ShadingPoint {
  Vec3 p;                // world position
  Vec3 ng;               // geometric normal, world, as modelled (not flipped towards the viewer)
  Frame frame;           // shading frame, world; frame.n on the same side as ng
  Vec2 uv;               // first texture coordinate set
  Vec2 uv1;              // second set (glTF TEXCOORD_1), equal to uv where absent
  Rgb vertex_color{1, 1, 1};
  bool front_face = true;  // the ray arrived on the side ng points to
};

class Texture {
 public:
  virtual ~Texture() = default;
  virtual Rgb eval(const ShadingPoint& sp) const = 0;
  // Mean value over the texture's domain (for light power estimates).
  virtual Rgb average() const = 0;
};

struct RgbParam {
  Rgb value{0, 0, 0};
  std::shared_ptr<const Texture> texture;  // when set, value multiplies the texture
  Rgb eval(const ShadingPoint& sp) const { return texture ? value * texture->eval(sp) : value; }
  Rgb average() const { return texture ? value * texture->average() : value; }
};

struct FloatParam {
  float value = 0;
  std::shared_ptr<const Texture> texture;  // when set, value multiplies the texture's first channel
  float eval(const ShadingPoint& sp) const { return texture ? value * texture->eval(sp).x : value; }
};

}  // namespace tessera
