// The list of built-in integrators. A new integrator adds its register function here.
#include "renderer/integrator.h"

namespace tessera {

void register_path(IntegratorRegistry& registry);
void register_bidirectional(IntegratorRegistry& registry);

void register_builtin_integrators(IntegratorRegistry& registry) {
  register_path(registry);
  register_bidirectional(registry);
}

}  // namespace tessera
