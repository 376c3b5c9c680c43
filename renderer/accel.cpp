#include "renderer/accel.h"

#include <embree3/rtcore.h>

#include <cmath>
#include <cstring>
#include <stdexcept>
#include <string>

#include "renderer/geometry.h"
#include "renderer/material/material.h"
#include "renderer/sampler.h"

namespace tessera {

namespace {

RTCDevice shared_device() {
  // One device for the process: Embree's devices own thread-local state and a TBB arena.
  static RTCDevice device = [] {
    RTCDevice d = rtcNewDevice("verbose=0");
    if (!d) throw std::runtime_error("Embree: could not create a device (rtcNewDevice failed)");
    return d;
  }();
  return device;
}

void check(RTCDevice device, const char* what) {
  RTCError err = rtcGetDeviceError(device);
  if (err != RTC_ERROR_NONE)
    throw std::runtime_error(std::string("Embree: ") + what + " failed (error " +
                             std::to_string(static_cast<int>(err)) + ")");
}

struct GeometryRef {
  bool is_sphere;
  uint32_t object;  // mesh, sphere or (in the top scene) instance index
  bool is_instance = false;
};

// Coverage test for masked and blended materials, run by Embree for every candidate hit (camera, bounce and
// shadow rays alike), so cut-outs neither show nor cast shadows.
struct AlphaUserData {
  const Mesh* mesh;
  const Material* material;
};

void alpha_filter(const RTCFilterFunctionNArguments* args) {
  const auto* data = static_cast<const AlphaUserData*>(args->geometryUserPtr);
  const Mesh& mesh = *data->mesh;
  for (unsigned i = 0; i < args->N; ++i) {
    if (args->valid[i] == 0) continue;
    const uint32_t prim = RTCHitN_primID(args->hit, args->N, i);
    const float b1 = RTCHitN_u(args->hit, args->N, i), b2 = RTCHitN_v(args->hit, args->N, i), b0 = 1 - b1 - b2;
    const uint32_t* idx = &mesh.indices[3 * prim];
    ShadingPoint sp;
    if (!mesh.uvs.empty()) sp.uv = mesh.uvs[idx[0]] * b0 + mesh.uvs[idx[1]] * b1 + mesh.uvs[idx[2]] * b2;
    sp.uv1 = mesh.uvs1.empty() ? sp.uv : mesh.uvs1[idx[0]] * b0 + mesh.uvs1[idx[1]] * b1 + mesh.uvs1[idx[2]] * b2;
    const float alpha = data->material->coverage(sp);
    bool keep;
    if (data->material->alpha_mode() == Material::AlphaMode::kMask) {
      keep = alpha >= data->material->alpha_cutoff();
    } else {
      // Blend: keep the hit with probability alpha, decided by a hash of the ray and the hit, so the decision is
      // deterministic (the same ray always sees the same surface) yet uncorrelated between rays.
      const float key[8] = {RTCRayN_org_x(args->ray, args->N, i),
                            RTCRayN_org_y(args->ray, args->N, i),
                            RTCRayN_org_z(args->ray, args->N, i),
                            RTCRayN_dir_x(args->ray, args->N, i),
                            RTCRayN_dir_y(args->ray, args->N, i),
                            RTCRayN_dir_z(args->ray, args->N, i),
                            b1,
                            b2};
      uint64_t h = prim;
      for (float f : key) {
        uint32_t bits;
        std::memcpy(&bits, &f, 4);
        h = mix64(h ^ bits);
      }
      keep = static_cast<float>(h >> 40) * 0x1p-24f < alpha;
    }
    if (!keep) args->valid[i] = 0;
  }
}

// Attaches a triangle geometry reading `mesh`'s arrays in place; returns its geometry id.
uint32_t attach_mesh(RTCDevice device, RTCScene scene, const Mesh& mesh, const Material* material,
                     std::vector<std::unique_ptr<AlphaUserData>>& alpha_data) {
  RTCGeometry geom = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
  if (material && material->alpha_mode() != Material::AlphaMode::kOpaque) {
    alpha_data.push_back(std::make_unique<AlphaUserData>(AlphaUserData{&mesh, material}));
    rtcSetGeometryUserData(geom, alpha_data.back().get());
    rtcSetGeometryIntersectFilterFunction(geom, &alpha_filter);
    rtcSetGeometryOccludedFilterFunction(geom, &alpha_filter);
  }
  // Shared buffers: Embree reads our arrays in place. Vertex buffers need 4 bytes readable past the last vertex
  // (Embree loads 16 bytes at a time), which Scene::finalize guarantees by reserving capacity. A moving mesh has one
  // vertex buffer per time step (slot i at ray time i / (steps - 1)), between which Embree interpolates linearly
  // (Embree 3 manual, "Motion Blur"); a still one has its positions alone, and rays' times do not matter to it.
  if (mesh.moves()) {
    rtcSetGeometryTimeStepCount(geom, static_cast<unsigned>(mesh.motion_positions.size()));
    for (unsigned step = 0; step < mesh.motion_positions.size(); ++step)
      rtcSetSharedGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, step, RTC_FORMAT_FLOAT3,
                                 mesh.motion_positions[step].data(), 0, sizeof(Vec3), mesh.positions.size());
  } else {
    rtcSetSharedGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, mesh.positions.data(), 0,
                               sizeof(Vec3), mesh.positions.size());
  }
  rtcSetSharedGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, mesh.indices.data(), 0,
                             3 * sizeof(uint32_t), mesh.triangle_count());
  rtcCommitGeometry(geom);
  uint32_t id = rtcAttachGeometry(scene, geom);
  rtcReleaseGeometry(geom);
  return id;
}

void set_ref(std::vector<GeometryRef>& refs, uint32_t id, GeometryRef ref) {
  if (refs.size() <= id) refs.resize(id + 1);
  refs[id] = ref;
}

}  // namespace

struct Accel::Impl {
  RTCScene scene = nullptr;
  std::vector<GeometryRef> refs;  // by Embree geometry id in the top scene
  std::vector<RTCScene> group_scenes;
  std::vector<std::vector<GeometryRef>> group_refs;        // by geometry id within each group scene
  std::vector<uint32_t> instance_group;                    // by instance index
  std::vector<std::unique_ptr<AlphaUserData>> alpha_data;  // filter-function user data, alive with the scenes
  void release() {
    if (scene) rtcReleaseScene(scene);
    for (RTCScene g : group_scenes) rtcReleaseScene(g);
    scene = nullptr;
    group_scenes.clear();
    group_refs.clear();
    refs.clear();
    instance_group.clear();
    alpha_data.clear();
  }
  ~Impl() { release(); }
};

Accel::Accel() : impl_(std::make_unique<Impl>()) {}
Accel::~Accel() = default;

void Accel::build(const std::vector<Mesh>& meshes, const std::vector<Sphere>& spheres,
                  const std::vector<MeshGroup>& groups, const std::vector<Instance>& instances,
                  const std::vector<const Material*>& materials) {
  RTCDevice device = shared_device();
  impl_->release();
  impl_->scene = rtcNewScene(device);
  // Medium quality traced as fast as high quality on our scenes and builds several times faster.
  rtcSetSceneBuildQuality(impl_->scene, RTC_BUILD_QUALITY_MEDIUM);
  rtcSetSceneFlags(impl_->scene, RTC_SCENE_FLAG_ROBUST);

  for (uint32_t m = 0; m < meshes.size(); ++m) {
    if (meshes[m].indices.empty() || meshes[m].prototype) continue;
    set_ref(impl_->refs, attach_mesh(device, impl_->scene, meshes[m], materials[meshes[m].material], impl_->alpha_data),
            {false, m});
    check(device, "triangle geometry");
  }
  for (uint32_t s = 0; s < spheres.size(); ++s) {
    RTCGeometry geom = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_SPHERE_POINT);
    float* v = static_cast<float*>(
        rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT4, 4 * sizeof(float), 1));
    v[0] = spheres[s].center.x;
    v[1] = spheres[s].center.y;
    v[2] = spheres[s].center.z;
    v[3] = spheres[s].radius;
    rtcCommitGeometry(geom);
    uint32_t id = rtcAttachGeometry(impl_->scene, geom);
    rtcReleaseGeometry(geom);
    set_ref(impl_->refs, id, {true, s});
    check(device, "sphere geometry");
  }
  // One Embree scene per group, shared by all of its instances.
  for (const MeshGroup& group : groups) {
    RTCScene gs = rtcNewScene(device);
    rtcSetSceneBuildQuality(gs, RTC_BUILD_QUALITY_MEDIUM);
    rtcSetSceneFlags(gs, RTC_SCENE_FLAG_ROBUST);
    std::vector<GeometryRef> refs;
    for (uint32_t m : group.meshes)
      if (!meshes[m].indices.empty())
        set_ref(refs, attach_mesh(device, gs, meshes[m], materials[meshes[m].material], impl_->alpha_data), {false, m});
    rtcCommitScene(gs);
    check(device, "instanced scene build");
    impl_->group_scenes.push_back(gs);
    impl_->group_refs.push_back(std::move(refs));
  }
  for (uint32_t i = 0; i < instances.size(); ++i) {
    const Instance& inst = instances[i];
    RTCGeometry geom = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_INSTANCE);
    rtcSetGeometryInstancedScene(geom, impl_->group_scenes.at(inst.group));
    rtcSetGeometryTransform(geom, 0, RTC_FORMAT_FLOAT3X4_ROW_MAJOR, &inst.to_world.m[0][0]);
    rtcCommitGeometry(geom);
    uint32_t id = rtcAttachGeometry(impl_->scene, geom);
    rtcReleaseGeometry(geom);
    set_ref(impl_->refs, id, {false, i, true});
    impl_->instance_group.push_back(inst.group);
    check(device, "instance");
  }
  rtcCommitScene(impl_->scene);
  check(device, "scene build");
}

// Fills `hit` from Embree's hit record; false when the ray hit nothing.
bool Accel::resolve(float t, float u, float v, Vec3 ng, uint32_t geom_id, uint32_t prim_id, uint32_t inst_id,
                    RayHit* hit) const {
  if (geom_id == RTC_INVALID_GEOMETRY_ID) return false;
  hit->t = t;
  hit->u = u;
  hit->v = v;
  hit->ng = ng;
  hit->geom_id = geom_id;
  hit->prim_id = prim_id;
  if (inst_id != RTC_INVALID_GEOMETRY_ID) {
    // Instanced: instID names the instance in the top scene, geomID the mesh within its group's scene.
    const GeometryRef& inst = impl_->refs[inst_id];
    hit->instance = inst.object;
    const GeometryRef& ref = impl_->group_refs[impl_->instance_group[inst.object]][geom_id];
    hit->is_sphere = false;
    hit->object = ref.object;
    return true;
  }
  const GeometryRef& ref = impl_->refs[geom_id];
  hit->is_sphere = ref.is_sphere;
  hit->object = ref.object;
  hit->instance = kNoInstance;
  return true;
}

namespace {

// Whether Embree may be given `ray`. Embree 3 asserts that every origin and direction component lies within
// +-1.844e18 (its FLT_LARGE) and that tnear and tfar are not NaN (RayK::valid), and the assertion aborts the process.
// A ray that fails (a NaN from a degenerate shading frame, say) is answered as one that hits nothing: the path ends,
// and the film drops a sample that is not a number.
bool traceable(const Ray& ray) {
  constexpr float kLarge = 1.844e18f;
  return std::abs(ray.origin.x) <= kLarge && std::abs(ray.origin.y) <= kLarge && std::abs(ray.origin.z) <= kLarge &&
         std::abs(ray.dir.x) <= kLarge && std::abs(ray.dir.y) <= kLarge && std::abs(ray.dir.z) <= kLarge &&
         !std::isnan(ray.tmin) && !std::isnan(ray.tmax);
}

}  // namespace

bool Accel::intersect(const Ray& ray, RayHit* hit) const {
  if (!traceable(ray)) return false;
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  RTCRayHit rh;
  rh.ray.org_x = ray.origin.x;
  rh.ray.org_y = ray.origin.y;
  rh.ray.org_z = ray.origin.z;
  rh.ray.dir_x = ray.dir.x;
  rh.ray.dir_y = ray.dir.y;
  rh.ray.dir_z = ray.dir.z;
  rh.ray.tnear = ray.tmin;
  rh.ray.tfar = ray.tmax;
  rh.ray.time = ray.time;
  rh.ray.mask = 0xffffffffu;
  rh.ray.id = 0;
  rh.ray.flags = 0;
  rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
  rtcIntersect1(impl_->scene, &ctx, &rh);
  return resolve(rh.ray.tfar, rh.hit.u, rh.hit.v, Vec3(rh.hit.Ng_x, rh.hit.Ng_y, rh.hit.Ng_z), rh.hit.geomID,
                 rh.hit.primID, rh.hit.instID[0], hit);
}

void Accel::intersect_packet(const Ray* rays, int count, RayHit* hits, bool* found) const {
  static_assert(kPacketSize == 8, "the packet is an RTCRayHit8");
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
  alignas(32) int valid[8];
  alignas(32) RTCRayHit8 rh;
  for (int i = 0; i < 8; ++i) {
    const Ray& ray = rays[i < count ? i : 0];
    valid[i] = i < count && traceable(ray) ? -1 : 0;
    rh.ray.org_x[i] = ray.origin.x;
    rh.ray.org_y[i] = ray.origin.y;
    rh.ray.org_z[i] = ray.origin.z;
    rh.ray.dir_x[i] = ray.dir.x;
    rh.ray.dir_y[i] = ray.dir.y;
    rh.ray.dir_z[i] = ray.dir.z;
    rh.ray.tnear[i] = ray.tmin;
    rh.ray.tfar[i] = ray.tmax;
    rh.ray.time[i] = ray.time;
    rh.ray.mask[i] = 0xffffffffu;
    rh.ray.id[i] = static_cast<unsigned>(i);
    rh.ray.flags[i] = 0;
    rh.hit.geomID[i] = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0][i] = RTC_INVALID_GEOMETRY_ID;
  }
  rtcIntersect8(valid, impl_->scene, &ctx, &rh);
  for (int i = 0; i < count; ++i)
    found[i] = valid[i] &&
               resolve(rh.ray.tfar[i], rh.hit.u[i], rh.hit.v[i], Vec3(rh.hit.Ng_x[i], rh.hit.Ng_y[i], rh.hit.Ng_z[i]),
                       rh.hit.geomID[i], rh.hit.primID[i], rh.hit.instID[0][i], &hits[i]);
}

bool Accel::occluded(const Ray& ray) const {
  if (!traceable(ray)) return false;
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  RTCRay r;
  r.org_x = ray.origin.x;
  r.org_y = ray.origin.y;
  r.org_z = ray.origin.z;
  r.dir_x = ray.dir.x;
  r.dir_y = ray.dir.y;
  r.dir_z = ray.dir.z;
  r.tnear = ray.tmin;
  r.tfar = ray.tmax;
  r.time = ray.time;
  r.mask = 0xffffffffu;
  r.id = 0;
  r.flags = 0;
  rtcOccluded1(impl_->scene, &ctx, &r);
  return r.tfar < 0;  // Embree sets tfar to -inf when an occluder was found
}

}  // namespace tessera
