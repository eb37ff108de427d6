/* Shadow-ray yardstick: casts the segments of a ray file through Embree 3
 * (rtcOccluded1, one ray at a time, single thread) and prints rays/s.
 *
 * Input (little endian, written by bench/perf_rays.rs):
 *   u64 ntri, then ntri * 9 f32 (triangle vertices, normalized frame),
 *   u64 nray, then nray * 8 f32 (origin xyz, direction xyz (unit), tnear, tfar).
 * Output: one line "embree rays N occluded K seconds S rays_per_s R".
 * Build: bench/embree/build.sh (needs Debian libembree-dev). Bench only, never a
 * product dependency. */
#include <embree3/rtcore.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>

static double now(void) {
  struct timespec t;
  clock_gettime(CLOCK_MONOTONIC, &t);
  return t.tv_sec + 1e-9 * t.tv_nsec;
}

int main(int argc, char **argv) {
  if (argc < 2) {
    fprintf(stderr, "usage: %s RAYFILE [repeats]\n", argv[0]);
    return 2;
  }
  int repeats = argc > 2 ? atoi(argv[2]) : 1;
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

  RTCDevice dev = rtcNewDevice("threads=1");
  RTCScene scene = rtcNewScene(dev);
  rtcSetSceneBuildQuality(scene, RTC_BUILD_QUALITY_HIGH);
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

  struct RTCIntersectContext ctx;
  uint64_t occluded = 0;
  double best = 1e30;
  for (int r = 0; r < repeats; r++) {
    occluded = 0;
    double t0 = now();
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
    double dt = now() - t0;
    if (dt < best) best = dt;
  }
  printf("embree rays %llu occluded %llu seconds %.4f rays_per_s %.4e\n",
         (unsigned long long)nr, (unsigned long long)occluded, best, nr / best);
  rtcReleaseScene(scene);
  rtcReleaseDevice(dev);
  free(tv);
  free(rv);
  return 0;
}
