/* The paper's ray-casting test through Embree 3, for scale: reads the triangles and segments
 * written by `hirad raybench SCENE --export FILE` and times rtcOccluded1 over all segments on
 * THREADS threads, each casting a contiguous share (median of 5 passes; build on one thread).
 * Not built by the project; see README.md. */
#include <embree3/rtcore.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

static double now(void) {
  struct timespec t;
  clock_gettime(CLOCK_MONOTONIC, &t);
  return t.tv_sec + 1e-9 * t.tv_nsec;
}

static int cmp(const void *a, const void *b) {
  double x = *(const double *)a, y = *(const double *)b;
  return x < y ? -1 : x > y;
}

static void *read_block(FILE *f, size_t size, unsigned *count, const char *what) {
  void *p;
  if (fread(count, 4, 1, f) != 1) { fprintf(stderr, "truncated file: %s count\n", what); exit(2); }
  p = malloc(size * (*count) + 1);
  if (!p || fread(p, size, *count, f) != *count) { fprintf(stderr, "truncated file: %s\n", what); exit(2); }
  return p;
}

struct job {
  RTCScene sc;
  const float *sg;
  unsigned begin, end, occluded;
};

static void *cast(void *arg) {
  struct job *j = arg;
  struct RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  j->occluded = 0;
  for (unsigned i = j->begin; i < j->end; i++) {
    const float *s = j->sg + 8 * (size_t)i;
    struct RTCRay r = {s[0], s[1], s[2], s[6], s[3], s[4], s[5], 0.0f, s[7], (unsigned)-1, 0, 0};
    rtcOccluded1(j->sc, &ctx, &r);
    j->occluded += r.tfar < 0.0f;
  }
  return NULL;
}

int main(int argc, char **argv) {
  if (argc < 2) { fprintf(stderr, "usage: %s FILE [medium|high] [THREADS] [robust]\n", argv[0]); return 2; }
  FILE *f = fopen(argv[1], "rb");
  if (!f) { perror(argv[1]); return 2; }
  unsigned nt, ns;
  float *tv = read_block(f, 36, &nt, "triangles");
  float *sg = read_block(f, 32, &ns, "segments");
  fclose(f);
  int high = argc > 2 && !strcmp(argv[2], "high");
  int nth = argc > 3 ? atoi(argv[3]) : 1;
  int robust = argc > 4 && !strcmp(argv[4], "robust");
  if (nth < 1 || nth > 256) { fprintf(stderr, "THREADS must be 1 to 256\n"); return 2; }
  RTCDevice dev = rtcNewDevice("threads=1");
  RTCScene sc = rtcNewScene(dev);
  RTCGeometry g = rtcNewGeometry(dev, RTC_GEOMETRY_TYPE_TRIANGLE);
  float *vb = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 12, 3 * (size_t)nt);
  unsigned *ib = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 12, nt);
  memcpy(vb, tv, 36 * (size_t)nt);
  for (unsigned i = 0; i < 3 * nt; i++) ib[i] = i;
  if (robust) rtcSetSceneFlags(sc, RTC_SCENE_FLAG_ROBUST);
  if (high) {
    rtcSetSceneBuildQuality(sc, RTC_BUILD_QUALITY_HIGH);
    rtcSetGeometryBuildQuality(g, RTC_BUILD_QUALITY_HIGH);
  }
  rtcCommitGeometry(g);
  rtcAttachGeometry(sc, g);
  rtcReleaseGeometry(g);
  double t0 = now();
  rtcCommitScene(sc);
  double build = now() - t0;
  double ts[5];
  unsigned occluded = 0;
  for (int rep = 0; rep < 5; rep++) {
    struct job jobs[256];
    pthread_t th[256];
    t0 = now();
    for (int k = 0; k < nth; k++) {
      jobs[k] = (struct job){sc, sg, (unsigned)((size_t)ns * k / nth), (unsigned)((size_t)ns * (k + 1) / nth), 0};
      if (k > 0) pthread_create(&th[k], NULL, cast, &jobs[k]);
    }
    cast(&jobs[0]);
    occluded = jobs[0].occluded;
    for (int k = 1; k < nth; k++) {
      pthread_join(th[k], NULL);
      occluded += jobs[k].occluded;
    }
    ts[rep] = now() - t0;
  }
  qsort(ts, 5, sizeof(double), cmp);
  printf("embree %s%s, %d thread%s: %u triangles, %u segments, build %.1f ms, query %.1f ms, %.3f Mrays/s, occluded %u\n",
         high ? "high" : "medium", robust ? " robust" : "", nth, nth > 1 ? "s" : "", nt, ns, build * 1e3, ts[2] * 1e3, ns / ts[2] / 1e6, occluded);
  rtcReleaseScene(sc);
  rtcReleaseDevice(dev);
  return 0;
}
