// A surface point a ray found: where it is, what it is made of and which light it is (the scene fills it in; shading,
// the integrators and the lights read it).
#pragma once

#include <cstdint>

#include "renderer/texture.h"

namespace tessera {

class Material;

// The light index of a surface that is no light.
inline constexpr uint32_t kNoLight = ~0u;

// A surface point found by a ray, with what shading needs.
struct SurfaceInteraction {
  ShadingPoint sp;
  const Material* material = nullptr;
  uint32_t light = kNoLight;  // its light index if the surface emits
  float t = 0;
  // Which object and material were hit, for the id passes: the object is the mesh, the sphere or the instance
  // (numbered meshes first, then spheres, then instances: every traced shape has its own number), the material its
  // index in Scene::materials.
  uint32_t object = 0;
  uint32_t material_index = 0;
};

}  // namespace tessera
