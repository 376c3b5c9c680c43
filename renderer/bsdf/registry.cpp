// The list of built-in material models. A new model adds its register function here.
#include "renderer/material.h"

namespace tessera {

void register_lambert(MaterialRegistry& registry);

void register_builtin_materials(MaterialRegistry& registry) { register_lambert(registry); }

}  // namespace tessera
