// The list of built-in material models. A new model adds its register function here.
#include "renderer/material/material.h"

namespace tessera {

void register_lambert(MaterialRegistry& registry);  // lambert, emission
void register_phong(MaterialRegistry& registry);    // phong, blinn_phong, phong_classic, blinn_phong_classic
void register_cook_torrance(MaterialRegistry& registry);
void register_ward(MaterialRegistry& registry);
void register_dielectric(MaterialRegistry& registry);  // dielectric, thin_dielectric, subsurface
void register_conductor(MaterialRegistry& registry);
void register_plastic(MaterialRegistry& registry);
void register_gltf_pbr(MaterialRegistry& registry);
void register_mix(MaterialRegistry& registry);
void register_two_sided(MaterialRegistry& registry);
void register_interface(MaterialRegistry& registry);

void register_builtin_materials(MaterialRegistry& registry) {
  register_lambert(registry);
  register_phong(registry);
  register_cook_torrance(registry);
  register_ward(registry);
  register_dielectric(registry);
  register_conductor(registry);
  register_plastic(registry);
  register_gltf_pbr(registry);
  register_mix(registry);
  register_two_sided(registry);
  register_interface(registry);
}

}  // namespace tessera
