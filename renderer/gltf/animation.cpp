// glTF animations (glTF 2.0, 3.11 "Animations"): an animation's channels and their samplers' keyframes read once,
// then evaluated at any time into a Pose (every node's local transform and morph weights) that the scene graph is
// walked with (gltf/nodes.cpp), so that skins, cameras and lights follow their animated nodes.
#include <algorithm>
#include <cmath>
#include <map>
#include <tuple>

#include "proto/did_you_mean.h"
#include "renderer/gltf/internal.h"

namespace tessera::gltf {

NodeTransform NodeTransform::of(const tinygltf::Node& node) {
  NodeTransform n;
  if (node.matrix.size() == 16) n.matrix = node.matrix;
  if (node.translation.size() == 3) std::copy(node.translation.begin(), node.translation.end(), n.translation);
  if (node.rotation.size() == 4) std::copy(node.rotation.begin(), node.rotation.end(), n.rotation);
  if (node.scale.size() == 3) std::copy(node.scale.begin(), node.scale.end(), n.scale);
  return n;
}

// A node's local transform: its matrix, or translation * rotation * scale (glTF 2.0, 5.25).
TransformD NodeTransform::local() const {
  if (matrix.size() == 16) return TransformD::from_column_major(matrix.data());
  return TransformD::from_trs(translation, rotation, scale);
}

Pose static_pose(const tinygltf::Model& model) {
  Pose pose;
  pose.nodes.reserve(model.nodes.size());
  for (const tinygltf::Node& node : model.nodes) pose.nodes.push_back(NodeTransform::of(node));
  pose.weights.resize(model.nodes.size());
  return pose;
}

namespace {

void normalise(double* q) {
  const double len = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
  if (len > 0 && std::isfinite(len))
    for (int c = 0; c < 4; ++c) q[c] /= len;
}

// Spherical linear interpolation from unit quaternion a to b at u in [0, 1] (Shoemake 1985, "Animating rotation with
// quaternion curves"; glTF 2.0, Appendix C "Spherical Linear Interpolation"): along the shorter arc, q and -q being
// the same rotation, so b is negated when the quaternions are more than 90 degrees apart in 4D. Nearly equal
// quaternions, where sin(angle) vanishes, are blended linearly. The result is normalised.
void slerp(const float* a, const float* b, double u, double* out) {
  double d = 0;
  for (int c = 0; c < 4; ++c) d += static_cast<double>(a[c]) * b[c];
  const double sign = d < 0 ? -1 : 1;
  d = std::min(std::abs(d), 1.0);
  double wa = 1 - u, wb = u;
  if (d < 1 - 1e-9) {
    const double angle = std::acos(d), s = std::sin(angle);
    wa = std::sin((1 - u) * angle) / s;
    wb = std::sin(u * angle) / s;
  }
  for (int c = 0; c < 4; ++c) out[c] = wa * a[c] + sign * wb * b[c];
  normalise(out);
}

}  // namespace

// glTF 2.0, Appendix C "Animation Sampler Interpolation Modes": between keyframes k and k + 1 at t_k <= t < t_k+1,
// with u = (t - t_k) / (t_k+1 - t_k):
//   STEP: v_k;
//   LINEAR: (1 - u) v_k + u v_k+1, or slerp(v_k, v_k+1, u) for rotations;
//   CUBICSPLINE: the cubic Hermite spline (2u^3 - 3u^2 + 1) v_k + td (u^3 - 2u^2 + u) b_k + (-2u^3 + 3u^2) v_k+1 +
//   td (u^3 - u^2) a_k+1, with td = t_k+1 - t_k, b_k the out-tangent of keyframe k and a_k+1 the in-tangent of the
//   next (tangents are per second, hence scaled by the interval); rotations normalised after.
// Before the first keyframe the first value holds, after the last the last.
void AnimationSampler::evaluate(double t, double* out) const {
  const size_t keys = times.size();
  const bool cubic = interpolation == Interpolation::kCubicSpline;
  // Keyframe k's value (the middle of a CUBICSPLINE triple).
  auto value = [&](size_t k) { return values.data() + (cubic ? 3 * k + 1 : k) * static_cast<size_t>(width); };
  auto copy = [&](const float* v) {
    for (int c = 0; c < width; ++c) out[c] = v[c];
    if (rotation && width == 4) normalise(out);
  };
  if (keys == 0) return;
  if (!(t > times.front())) return copy(value(0));  // also a NaN time
  if (t >= times.back()) return copy(value(keys - 1));
  const size_t k = static_cast<size_t>(std::upper_bound(times.begin(), times.end(), t) - times.begin()) - 1;
  const double t0 = times[k], t1 = times[k + 1], td = t1 - t0;
  const double u = std::clamp((t - t0) / td, 0.0, 1.0);
  switch (interpolation) {
    case Interpolation::kStep:
      return copy(value(k));
    case Interpolation::kLinear:
      if (rotation && width == 4) return slerp(value(k), value(k + 1), u, out);
      for (int c = 0; c < width; ++c) out[c] = (1 - u) * value(k)[c] + u * value(k + 1)[c];
      return;
    case Interpolation::kCubicSpline: {
      const float* b0 = values.data() + (3 * k + 2) * static_cast<size_t>(width);    // out-tangent of k
      const float* a1 = values.data() + (3 * (k + 1)) * static_cast<size_t>(width);  // in-tangent of k + 1
      const double u2 = u * u, u3 = u2 * u;
      const double h00 = 2 * u3 - 3 * u2 + 1, h10 = u3 - 2 * u2 + u, h01 = -2 * u3 + 3 * u2, h11 = u3 - u2;
      for (int c = 0; c < width; ++c)
        out[c] = h00 * value(k)[c] + h10 * td * b0[c] + h01 * value(k + 1)[c] + h11 * td * a1[c];
      if (rotation && width == 4) normalise(out);
      return;
    }
  }
}

void Animation::pose_at(double t, Pose& pose) const {
  for (const AnimationChannel& ch : channels) {
    const AnimationSampler& s = samplers[ch.sampler];
    NodeTransform& n = pose.nodes[ch.node];
    switch (ch.path) {
      case AnimationChannel::Path::kTranslation:
        s.evaluate(t, n.translation);
        break;
      case AnimationChannel::Path::kRotation:
        s.evaluate(t, n.rotation);
        break;
      case AnimationChannel::Path::kScale:
        s.evaluate(t, n.scale);
        break;
      case AnimationChannel::Path::kWeights: {
        std::vector<double>& w = pose.weights[ch.node];
        w.resize(static_cast<size_t>(s.width));
        s.evaluate(t, w.data());
        break;
      }
    }
  }
}

Animation read_animation(Import& import, const AccessorReader& reader, int index) {
  const tinygltf::Model& model = import.model;
  const tinygltf::Animation& source = model.animations.at(static_cast<size_t>(index));
  const std::string what = "animation " + std::to_string(index);
  Animation animation;
  animation.name = source.name;
  // Each sampler is read once per way it is read (a sampler shared by channels of one kind is read once).
  std::map<std::tuple<int, int, bool>, int> read;
  for (size_t c = 0; c < source.channels.size(); ++c) {
    import.check_stop();
    const tinygltf::AnimationChannel& ch = source.channels[c];
    const std::string at = what + " channel " + std::to_string(c);
    AnimationChannel channel;
    // A channel without a node or with another path (KHR_animation_pointer's "pointer") targets nothing here.
    if (ch.target_node < 0) continue;
    if (ch.target_node >= static_cast<int>(model.nodes.size()))
      import.fail(at + " targets node " + std::to_string(ch.target_node) + ", which does not exist");
    channel.node = ch.target_node;
    const tinygltf::Node& node = model.nodes[ch.target_node];
    int components = 3, width = 3;
    if (ch.target_path == "translation") {
      channel.path = AnimationChannel::Path::kTranslation;
    } else if (ch.target_path == "rotation") {
      channel.path = AnimationChannel::Path::kRotation;
      components = width = 4;
    } else if (ch.target_path == "scale") {
      channel.path = AnimationChannel::Path::kScale;
    } else if (ch.target_path == "weights") {
      channel.path = AnimationChannel::Path::kWeights;
      components = 1;
      // One weight per morph target of the node's mesh (glTF 2.0, 3.11: the output holds that many per keyframe).
      width = 0;
      if (node.mesh >= 0 && node.mesh < static_cast<int>(model.meshes.size()) &&
          !model.meshes[node.mesh].primitives.empty())
        width = static_cast<int>(model.meshes[node.mesh].primitives[0].targets.size());
      if (width == 0) {
        import.warn(at + " animates the morph weights of node " + std::to_string(ch.target_node) +
                    ", whose mesh has no morph targets (ignored)");
        continue;
      }
    } else {
      continue;
    }
    // glTF 2.0, 3.11: a node targeted by an animation must not have a matrix (its TRS properties are what moves).
    if (channel.path != AnimationChannel::Path::kWeights && node.matrix.size() == 16) {
      import.warn(at + " animates node " + std::to_string(ch.target_node) +
                  ", which has a matrix: the specification does not allow it (ignored)");
      continue;
    }
    if (ch.sampler < 0 || ch.sampler >= static_cast<int>(source.samplers.size()))
      import.fail(at + " names sampler " + std::to_string(ch.sampler) + ", which does not exist");
    const bool rotation = channel.path == AnimationChannel::Path::kRotation;
    auto [it, fresh] = read.try_emplace({ch.sampler, width, rotation}, static_cast<int>(animation.samplers.size()));
    channel.sampler = it->second;
    animation.channels.push_back(channel);
    if (!fresh) continue;

    const tinygltf::AnimationSampler& src = source.samplers[ch.sampler];
    const std::string sat = what + " sampler " + std::to_string(ch.sampler);
    AnimationSampler sampler;
    sampler.width = width;
    sampler.rotation = rotation;
    if (src.interpolation == "LINEAR")
      sampler.interpolation = AnimationSampler::Interpolation::kLinear;
    else if (src.interpolation == "STEP")
      sampler.interpolation = AnimationSampler::Interpolation::kStep;
    else if (src.interpolation == "CUBICSPLINE")
      sampler.interpolation = AnimationSampler::Interpolation::kCubicSpline;
    else
      import.fail(sat + " has the unknown interpolation \"" + src.interpolation + "\"");
    sampler.times = reader.floats(src.input, 1);
    if (sampler.times.empty()) import.fail(sat + " has no keyframes");
    for (size_t k = 1; k < sampler.times.size(); ++k)
      if (!(sampler.times[k] > sampler.times[k - 1]))
        import.fail(sat + ": its keyframe times are not strictly increasing (at keyframe " + std::to_string(k) + ")");
    const bool cubic = sampler.interpolation == AnimationSampler::Interpolation::kCubicSpline;
    const size_t expected = sampler.times.size() * (cubic ? 3 : 1) * static_cast<size_t>(width);
    if (reader.count(src.output) * static_cast<size_t>(components) != expected)
      import.fail(sat + ": its output holds " + std::to_string(reader.count(src.output) * components) +
                  " values where " + std::to_string(sampler.times.size()) + " keyframes of " + ch.target_path +
                  (cubic ? " (in-tangent, value, out-tangent)" : "") + " need " + std::to_string(expected));
    sampler.values = reader.floats(src.output, components);
    animation.samplers.push_back(std::move(sampler));
  }
  return animation;
}

std::optional<Animation> chosen_animation(Import& import) {
  const std::vector<tinygltf::Animation>& animations = import.model.animations;
  const GltfImportOptions& options = import.options;
  const size_t count = animations.size();
  auto describe = [&](int i) {
    return "animation " + std::to_string(i) +
           (animations[i].name.empty() ? std::string() : " (\"" + animations[i].name + "\")");
  };
  if (!options.animate) {
    if (count > 0)
      import.warn("the asset's " + std::to_string(count) + (count == 1 ? " animation is" : " animations are") +
                  " not applied: its nodes are rendered as they are stated (scene.time or scene.animation poses them)");
    return std::nullopt;
  }
  const std::string& at = options.animation_pointer.empty() ? import.pointer : options.animation_pointer;
  int index = 0;
  if (!options.animation_name.empty()) {
    std::vector<std::string> names;
    for (const tinygltf::Animation& a : animations) names.push_back(a.name);
    const auto it = std::find(names.begin(), names.end(), options.animation_name);
    if (it == names.end()) {
      if (count == 0) throw SceneError(at, "the glTF asset has no animations");
      std::string known;
      for (size_t i = 0; i < names.size() && i < 20; ++i) known += (known.empty() ? "\"" : ", \"") + names[i] + "\"";
      if (names.size() > 20) known += " and " + std::to_string(names.size() - 20) + " more";
      throw SceneError(at, "the glTF asset has no animation \"" + options.animation_name + "\"" +
                               proto::did_you_mean(options.animation_name, names) + "; its animations: " + known);
    }
    index = static_cast<int>(it - names.begin());
  } else if (options.animation_index >= 0) {
    if (static_cast<size_t>(options.animation_index) >= count)
      throw SceneError(at, "the glTF asset has " + std::to_string(count) + " animations: there is no animation " +
                               std::to_string(options.animation_index));
    index = options.animation_index;
  } else if (count == 0) {
    if (!options.frames_pointer.empty())
      throw SceneError(options.frames_pointer, "the glTF asset has no animations: a frame range renders an animation");
    import.warn("scene.time poses nothing: the glTF asset has no animations");
    return std::nullopt;
  }
  if (count > 1)
    import.warn("the asset has " + std::to_string(count) + " animations; only " + describe(index) +
                " is applied (scene.animation chooses another)");
  const AccessorReader reader(import.model, import.pointer, import.decoded);
  return read_animation(import, reader, index);
}

}  // namespace tessera::gltf
