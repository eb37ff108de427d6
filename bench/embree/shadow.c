/* Shadow-ray yardstick: casts the segments of a ray file through Embree 3
 * (single thread) and prints rays/s: one ray at a time (rtcOccluded1), or with
 * PACKET = 4, 8 or 16 in consecutive groups of PACKET rays through Embree's packet
 * traversal (rtcOccluded4/8/16).
 *
 * Input (little endian, written by bench/perf_rays.rs):
 *   u64 ntri, then ntri * 9 f32 (triangle vertices, normalized frame),
 *   u64 nray, then nray * 8 f32 (origin xyz, direction xyz (unit), tnear, tfar).
 * Usage: embree-shadow RAYFILE [REPEATS [PACKET]].
 * Output: one line "embree rays N occluded K seconds S rays_per_s R" (with
 * "packets of PACKET" after "embree" in packet mode). On stderr: the bytes Embree
 * holds after building the scene (its buffers and BVH, from the device's memory
 * monitor).
 * EMBREE_BUILD_QUALITY=low|medium|high (default high) sets the build quality
 * (high: spatial splits), to see whether the tree's quality decides the rate.
 * EMBREE_VERBOSE=1 makes the device verbose (its config "verbose=2"): Embree then
 * prints its BVH's statistics on stdout after the build (depth, nodes, leaves, SAH
 * cost), to compare with ours (bench/PERF.md section 12).
 * Build: bench/embree/build.sh (needs Debian libembree-dev). Bench only, never a
 * product dependency. */
#include <embree3/rtcore.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/types.h>
#include <time.h>

/* Bytes Embree has allocated (its memory monitor callback keeps the count). */
static long long embree_bytes = 0;

static bool count_bytes(void *user, ssize_t bytes, bool post) {
  (void)user;
  (void)post;
  embree_bytes += bytes;
  return true;
}

static double now(void) {
  struct timespec t;
  clock_gettime(CLOCK_MONOTONIC, &t);
  return t.tv_sec + 1e-9 * t.tv_nsec;
}

/* Fills lane l of a packet of n rays (SoA: org x y z, tnear, dir x y z, time, tfar,
 * mask, id, flags) from ray record q. */
#define FILL(R, l, q)                                                              \
  do {                                                                             \
    (R).org_x[l] = (q)[0];                                                         \
    (R).org_y[l] = (q)[1];                                                         \
    (R).org_z[l] = (q)[2];                                                         \
    (R).dir_x[l] = (q)[3];                                                         \
    (R).dir_y[l] = (q)[4];                                                         \
    (R).dir_z[l] = (q)[5];                                                         \
    (R).tnear[l] = (q)[6];                                                         \
    (R).tfar[l] = (q)[7];                                                          \
    (R).time[l] = 0.0f;                                                            \
    (R).mask[l] = 0xFFFFFFFF;                                                      \
    (R).id[l] = 0;                                                                 \
    (R).flags[l] = 0;                                                              \
  } while (0)

/* Casts the rays in consecutive groups of `packet` (the last group partly valid);
 * returns how many are occluded. */
static uint64_t cast_packets(RTCScene scene, const float *rv, uint64_t nr, int packet) {
  struct RTCIntersectContext ctx;
  uint64_t occluded = 0;
  for (uint64_t k = 0; k < nr; k += packet) {
    int n = nr - k < (uint64_t)packet ? (int)(nr - k) : packet;
    int valid[16];
    for (int l = 0; l < packet; l++) valid[l] = l < n ? -1 : 0;
    rtcInitIntersectContext(&ctx);
    if (packet == 4) {
      struct RTCRay4 r;
      for (int l = 0; l < n; l++) FILL(r, l, rv + 8 * (k + l));
      rtcOccluded4(valid, scene, &ctx, &r);
      for (int l = 0; l < n; l++) occluded += r.tfar[l] < 0.0f;
    } else if (packet == 8) {
      struct RTCRay8 r;
      for (int l = 0; l < n; l++) FILL(r, l, rv + 8 * (k + l));
      rtcOccluded8(valid, scene, &ctx, &r);
      for (int l = 0; l < n; l++) occluded += r.tfar[l] < 0.0f;
    } else {
      struct RTCRay16 r;
      for (int l = 0; l < n; l++) FILL(r, l, rv + 8 * (k + l));
      rtcOccluded16(valid, scene, &ctx, &r);
      for (int l = 0; l < n; l++) occluded += r.tfar[l] < 0.0f;
    }
  }
  return occluded;
}

int main(int argc, char **argv) {
  if (argc < 2) {
    fprintf(stderr, "usage: %s RAYFILE [repeats [packet: 4, 8 or 16]]\n", argv[0]);
    return 2;
  }
  int repeats = argc > 2 ? atoi(argv[2]) : 1;
  int packet = argc > 3 ? atoi(argv[3]) : 1;
  if (packet != 1 && packet != 4 && packet != 8 && packet != 16) {
    fprintf(stderr, "packet size %d: 1, 4, 8 or 16\n", packet);
    return 2;
  }
  FILE *f = fopen(argv[1], "rb");
  if (!f) {
    perror(argv[1]);
    return 1;
  }
  uint64_t nt, nr;
  if (fread(&nt, 8, 1, f) != 1) return 1;
  float *tv = malloc(nt * 9 * sizeof(float));
  if (fread(tv, sizeof(float), nt * 9, f) != nt * 9) return 1;
  if (fread(&nr, 8, 1, f) != 1) return 1;
  float *rv = malloc(nr * 8 * sizeof(float));
  if (fread(rv, sizeof(float), nr * 8, f) != nr * 8) return 1;
  fclose(f);

  const char *verbose = getenv("EMBREE_VERBOSE");
  bool loud = verbose && strcmp(verbose, "1") == 0;
  RTCDevice dev = rtcNewDevice(loud ? "threads=1,verbose=2" : "threads=1");
  rtcSetDeviceMemoryMonitorFunction(dev, count_bytes, NULL);
  RTCScene scene = rtcNewScene(dev);
  enum RTCBuildQuality quality = RTC_BUILD_QUALITY_HIGH;
  const char *q_env = getenv("EMBREE_BUILD_QUALITY");
  if (q_env && strcmp(q_env, "low") == 0) {
    quality = RTC_BUILD_QUALITY_LOW;
  } else if (q_env && strcmp(q_env, "medium") == 0) {
    quality = RTC_BUILD_QUALITY_MEDIUM;
  } else if (q_env && strcmp(q_env, "high") != 0) {
    fprintf(stderr, "EMBREE_BUILD_QUALITY=%s: low, medium or high\n", q_env);
    return 2;
  }
  rtcSetSceneBuildQuality(scene, quality);
  RTCGeometry g = rtcNewGeometry(dev, RTC_GEOMETRY_TYPE_TRIANGLE);
  float *vb = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                      3 * sizeof(float), nt * 3);
  unsigned *ib = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                         3 * sizeof(unsigned), nt);
  for (uint64_t k = 0; k < nt * 9; k++) vb[k] = tv[k];
  for (uint64_t k = 0; k < nt * 3; k++) ib[k] = (unsigned)k;
  rtcCommitGeometry(g);
  rtcAttachGeometry(scene, g);
  rtcReleaseGeometry(g);
  rtcCommitScene(scene);
  fprintf(stderr, "embree memory after commit: %lld bytes\n", embree_bytes);

  struct RTCIntersectContext ctx;
  uint64_t occluded = 0;
  double best = 1e30;
  for (int r = 0; r < repeats; r++) {
    occluded = 0;
    double t0 = now();
    if (packet > 1) {
      occluded = cast_packets(scene, rv, nr, packet);
    } else {
      for (uint64_t k = 0; k < nr; k++) {
        const float *q = rv + 8 * k;
        struct RTCRay ray;
        ray.org_x = q[0];
        ray.org_y = q[1];
        ray.org_z = q[2];
        ray.dir_x = q[3];
        ray.dir_y = q[4];
        ray.dir_z = q[5];
        ray.tnear = q[6];
        ray.tfar = q[7];
        ray.time = 0.0f;
        ray.mask = 0xFFFFFFFF;
        ray.id = 0;
        ray.flags = 0;
        rtcInitIntersectContext(&ctx);
        rtcOccluded1(scene, &ctx, &ray);
        if (ray.tfar < 0.0f) occluded++;
      }
    }
    double dt = now() - t0;
    if (dt < best) best = dt;
  }
  if (packet > 1) printf("embree packets of %d ", packet);
  else printf("embree ");
  printf("rays %llu occluded %llu seconds %.4f rays_per_s %.4e\n",
         (unsigned long long)nr, (unsigned long long)occluded, best, nr / best);
  rtcReleaseScene(scene);
  rtcReleaseDevice(dev);
  free(tv);
  free(rv);
  return 0;
}
