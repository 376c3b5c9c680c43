#include "renderer/material/common.h"

#include "renderer/scene_error.h"

namespace tessera {

RoughnessParams read_roughness(const nlohmann::json& j, const std::string& ptr, const MaterialContext& ctx,
                               float default_roughness, bool allow_v_cavity) {
  RoughnessParams r;
  std::string dist = params::string(j, "distribution", ptr, allow_v_cavity ? "beckmann" : "ggx");
  if (dist == "ggx")
    r.type = MicrofacetType::kGgx;
  else if (dist == "beckmann")
    r.type = MicrofacetType::kBeckmann;
  else
    throw SceneError(ptr + "/distribution", "must be \"ggx\" or \"beckmann\"");
  if (allow_v_cavity) {
    std::string masking = params::string(j, "masking", ptr, "smith");
    if (masking == "smith")
      r.masking = MaskingType::kSmith;
    else if (masking == "v_cavity")
      r.masking = MaskingType::kVCavity;
    else
      throw SceneError(ptr + "/masking", "must be \"smith\" or \"v_cavity\"");
  }
  FloatParam rough = params::float_param(j, "roughness", ptr, default_roughness, 0.0f, 1.0f, ctx);
  r.alpha_x = j.contains("alpha_x") ? params::float_param(j, "alpha_x", ptr, 0, 0.0f, 1.0f, ctx) : rough;
  r.alpha_y = j.contains("alpha_y") ? params::float_param(j, "alpha_y", ptr, 0, 0.0f, 1.0f, ctx) : r.alpha_x;
  return r;
}

}  // namespace tessera
