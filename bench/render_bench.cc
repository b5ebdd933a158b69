// Rendering speed: the exact z-buffer rasteriser on the default template (~12.5k vertices,
// ~25k triangles) at the depth camera's 640 x 480 and the paper's 1600 x 2032 colour
// resolution; the same primary visibility by Embree ray casting (BVH build + one ray per
// pixel; loaded at run time when libembree3 is present); and the virtual Kinect's frames.
#include <benchmark/benchmark.h>
#include <dlfcn.h>
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>

#include <cmath>
#include <map>
#include <memory>
#include <utility>

#include "models/skinning.h"
#include "models/template_generator.h"
#include "render/rasterizer.h"
#include "sensors/subject_texture.h"
#include "sensors/virtual_kinect.h"

#if __has_include(<embree3/rtcore.h>)
#include <embree3/rtcore.h>
#define ARTEX_BENCH_EMBREE 1
#endif

namespace artex {
namespace {

// The last benchmark argument is the number of threads (TBB). With 1 thread all work runs
// on the benchmark's thread, so its CPU time is the single-core cost even on a busy machine.
tbb::global_control Threads(const benchmark::State& state, int arg) {
  return tbb::global_control(tbb::global_control::max_allowed_parallelism,
                             static_cast<size_t>(state.range(arg)));
}

const Template& Body() {
  static const Template body = GenerateTemplate();
  return body;
}

// A camera at 2.5 m in front of the body, looking at its centre; the vertical field of view
// covers ~2.3 m at the body.
PinholeCamera Camera(int width, int height) {
  PinholeCamera c;
  c.width = width;
  c.height = height;
  c.fy = c.fx = 525.0 * height / 480.0;
  c.cx = 0.5 * (width - 1);
  c.cy = 0.5 * (height - 1);
  c.world_to_camera = PinholeCamera::LookAt(Eigen::Vector3d(0.3, 1.2, 2.5),
                                            Eigen::Vector3d(0, 0.9, 0), Eigen::Vector3d::UnitY());
  return c;
}

void BM_Rasterize(benchmark::State& state) {
  const Template& body = Body();
  const PinholeCamera camera =
      Camera(static_cast<int>(state.range(0)), static_cast<int>(state.range(1)));
  const tbb::global_control threads = Threads(state, 2);
  RasterBuffers buffers;
  for (auto _ : state) {
    Rasterize(body.vertices, body.triangles, camera, RasterOptions(), &buffers);
    benchmark::DoNotOptimize(buffers.depth.data());
  }
  int hits = 0;
  for (int id : buffers.triangle_id) hits += id >= 0;
  state.counters["covered_px"] = hits;
  state.counters["triangles"] = body.num_triangles();
}
BENCHMARK(BM_Rasterize)
    ->Args({640, 480, 1})
    ->Args({640, 480, 2})
    ->Args({1600, 2032, 1})
    ->Args({1600, 2032, 2})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

#ifdef ARTEX_BENCH_EMBREE
// Embree entry points, resolved with dlopen so the build does not depend on Embree.
struct EmbreeApi {
  void* handle = nullptr;
  decltype(&rtcNewDevice) NewDevice;
  decltype(&rtcReleaseDevice) ReleaseDevice;
  decltype(&rtcNewScene) NewScene;
  decltype(&rtcReleaseScene) ReleaseScene;
  decltype(&rtcNewGeometry) NewGeometry;
  decltype(&rtcReleaseGeometry) ReleaseGeometry;
  decltype(&rtcSetNewGeometryBuffer) SetNewGeometryBuffer;
  decltype(&rtcCommitGeometry) CommitGeometry;
  decltype(&rtcAttachGeometry) AttachGeometry;
  decltype(&rtcCommitScene) CommitScene;
  decltype(&rtcIntersect1) Intersect1;

  bool Load() {
    handle = dlopen("libembree3.so.3", RTLD_NOW | RTLD_LOCAL);
    if (!handle) return false;
    auto get = [&](auto* fn, const char* name) {
      *fn = reinterpret_cast<std::remove_pointer_t<decltype(fn)>>(dlsym(handle, name));
      return *fn != nullptr;
    };
    return get(&NewDevice, "rtcNewDevice") && get(&ReleaseDevice, "rtcReleaseDevice") &&
           get(&NewScene, "rtcNewScene") && get(&ReleaseScene, "rtcReleaseScene") &&
           get(&NewGeometry, "rtcNewGeometry") && get(&ReleaseGeometry, "rtcReleaseGeometry") &&
           get(&SetNewGeometryBuffer, "rtcSetNewGeometryBuffer") &&
           get(&CommitGeometry, "rtcCommitGeometry") && get(&AttachGeometry, "rtcAttachGeometry") &&
           get(&CommitScene, "rtcCommitScene") && get(&Intersect1, "rtcIntersect1");
  }
};

// Per frame (the body deforms every frame): build the BVH, then one primary ray per pixel
// centre, returning depth, triangle id and barycentrics like the rasteriser.
void BM_EmbreeRayCast(benchmark::State& state) {
  static EmbreeApi api;
  static const bool loaded = api.Load();
  if (!loaded) {
    state.SkipWithError("libembree3.so.3 not found");
    return;
  }
  const Template& body = Body();
  const PinholeCamera camera =
      Camera(static_cast<int>(state.range(0)), static_cast<int>(state.range(1)));
  const tbb::global_control threads = Threads(state, 2);
  RTCDevice device = api.NewDevice(state.range(2) == 1 ? "threads=1" : nullptr);
  const Eigen::Matrix3d cam_to_world = camera.world_to_camera.linear().transpose();
  const Eigen::Vector3d origin = camera.Center();
  RasterBuffers out;
  out.width = camera.width;
  out.height = camera.height;
  out.depth.resize(static_cast<size_t>(camera.width) * camera.height);
  out.triangle_id.resize(out.depth.size());
  out.barycentric.resize(out.depth.size());
  for (auto _ : state) {
    RTCScene scene = api.NewScene(device);
    RTCGeometry geometry = api.NewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
    auto* v = static_cast<float*>(api.SetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_VERTEX, 0,
                                                           RTC_FORMAT_FLOAT3, 3 * sizeof(float),
                                                           body.num_vertices()));
    auto* t = static_cast<unsigned*>(
        api.SetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                 3 * sizeof(unsigned), body.num_triangles()));
    for (int i = 0; i < body.num_vertices(); ++i) {
      for (int k = 0; k < 3; ++k) v[3 * i + k] = static_cast<float>(body.vertices(i, k));
    }
    for (int f = 0; f < body.num_triangles(); ++f) {
      for (int k = 0; k < 3; ++k) t[3 * f + k] = static_cast<unsigned>(body.triangles(f, k));
    }
    api.CommitGeometry(geometry);
    api.AttachGeometry(scene, geometry);
    api.ReleaseGeometry(geometry);
    api.CommitScene(scene);
    tbb::parallel_for(0, camera.height, [&](int y) {
      RTCIntersectContext context;
      rtcInitIntersectContext(&context);
      for (int x = 0; x < camera.width; ++x) {
        const Eigen::Vector3d dir =
            cam_to_world *
            Eigen::Vector3d((x - camera.cx) / camera.fx, (y - camera.cy) / camera.fy, 1.0);
        RTCRayHit rh;
        rh.ray.org_x = static_cast<float>(origin.x());
        rh.ray.org_y = static_cast<float>(origin.y());
        rh.ray.org_z = static_cast<float>(origin.z());
        rh.ray.dir_x = static_cast<float>(dir.x());
        rh.ray.dir_y = static_cast<float>(dir.y());
        rh.ray.dir_z = static_cast<float>(dir.z());
        rh.ray.tnear = 0.05f;
        rh.ray.tfar = std::numeric_limits<float>::infinity();
        rh.ray.mask = static_cast<unsigned>(-1);
        rh.ray.flags = 0;
        rh.ray.time = 0;
        rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
        api.Intersect1(scene, &context, &rh);
        const size_t i = static_cast<size_t>(y) * camera.width + x;
        const bool hit = rh.hit.geomID != RTC_INVALID_GEOMETRY_ID;
        out.depth[i] = hit ? rh.ray.tfar : std::numeric_limits<float>::infinity();  // z: dir.z = 1
        out.triangle_id[i] = hit ? static_cast<int32_t>(rh.hit.primID) : -1;
        out.barycentric[i] = Eigen::Vector2f(rh.hit.u, rh.hit.v);
      }
    });
    api.ReleaseScene(scene);
    benchmark::DoNotOptimize(out.depth.data());
  }
  api.ReleaseDevice(device);

  // Agreement with the rasteriser (pixels whose visible triangle differs).
  RasterBuffers raster;
  Rasterize(body.vertices, body.triangles, camera, RasterOptions(), &raster);
  int differ = 0, hits = 0;
  for (size_t i = 0; i < raster.triangle_id.size(); ++i) {
    differ += raster.triangle_id[i] != out.triangle_id[i];
    hits += raster.triangle_id[i] >= 0;
  }
  state.counters["covered_px"] = hits;
  state.counters["id_differs_px"] = differ;
}
BENCHMARK(BM_EmbreeRayCast)
    ->Args({640, 480, 1})
    ->Args({640, 480, 2})
    ->Args({1600, 2032, 1})
    ->Args({1600, 2032, 2})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
#endif

// One subject (generated once) rendered by virtual Kinects with different colour sizes.
const SynthSubject& Subject() {
  static const SynthSubject subject = [] {
    SynthOptions o;
    o.motion.frames = 2;
    return PrepareSynthSubject(o);
  }();
  return subject;
}

struct KinectFixture {
  KinectFixture(int color_width, int color_height) {
    VirtualKinectOptions o;
    o.color_width = color_width;
    o.color_height = color_height;
    kinect = std::make_unique<VirtualKinect>(o, Subject().subject, Subject().texture_bgr);
    Skinning(Subject().subject).Apply(Subject().poses[1], &posed);
  }
  std::unique_ptr<VirtualKinect> kinect;
  Eigen::MatrixX3d posed;
};

KinectFixture& Fixture(int color_width, int color_height) {
  static std::map<std::pair<int, int>, std::unique_ptr<KinectFixture>> fixtures;
  auto& f = fixtures[{color_width, color_height}];
  if (!f) f = std::make_unique<KinectFixture>(color_width, color_height);
  return *f;
}

void BM_VirtualKinectDepth(benchmark::State& state) {
  KinectFixture& fixture = Fixture(800, 1016);
  const tbb::global_control threads = Threads(state, 0);
  for (auto _ : state) {
    const cv::Mat depth = fixture.kinect->RenderDepth(1, &fixture.posed);
    benchmark::DoNotOptimize(depth.data);
  }
}
BENCHMARK(BM_VirtualKinectDepth)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_VirtualKinectColor(benchmark::State& state) {
  KinectFixture& fixture =
      Fixture(static_cast<int>(state.range(0)), static_cast<int>(state.range(1)));
  const ColorConditions conditions;
  const tbb::global_control threads = Threads(state, 2);
  for (auto _ : state) {
    const cv::Mat color = fixture.kinect->RenderColor(1, &fixture.posed, conditions);
    benchmark::DoNotOptimize(color.data);
  }
}
BENCHMARK(BM_VirtualKinectColor)
    ->Args({800, 1016, 1})
    ->Args({800, 1016, 2})
    ->Args({1600, 2032, 1})
    ->Args({1600, 2032, 2})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

void BM_SubjectTexture(benchmark::State& state) {
  SubjectTextureOptions o;
  o.size = static_cast<int>(state.range(0));
  const tbb::global_control threads = Threads(state, 1);
  for (auto _ : state) {
    const cv::Mat texture = GenerateSubjectTexture(Body(), o);
    benchmark::DoNotOptimize(texture.data);
  }
}
BENCHMARK(BM_SubjectTexture)
    ->Args({1024, 1})
    ->Args({2048, 1})
    ->Args({2048, 2})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

}  // namespace
}  // namespace artex
