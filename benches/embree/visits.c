/* Tree quality of Embree 3's own builder, for comparison with `hirad raybench`'s counts: builds an
 * eight-wide BVH over the triangles of FILE with `rtcBuildBVH` (SAH, medium quality; BLOCK =
 * sahBlockSize, leaves of MINLEAF to MAXLEAF triangles), then walks every segment of FILE as an
 * occlusion query (hit children in build order, stop at the first hit; box and triangle tests in
 * double precision) and prints inner-node visits, leaf visits and triangle tests per segment.
 * `raybench`'s nodes per ray count inner nodes and leaves together. Not built by the project;
 * see README.md. */
#include <embree3/rtcore.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <math.h>
typedef struct Node { int leaf; unsigned n; float b[8][6]; void *c[8]; } Node;
typedef struct Leaf { int leaf; unsigned n; unsigned id[]; } Leaf;
static void *create_node(RTCThreadLocalAllocator a, unsigned n, void *u) {
  Node *p = rtcThreadLocalAlloc(a, sizeof(Node), 16); p->leaf = 0; p->n = n; return p; }
static void set_children(void *np, void **c, unsigned n, void *u) { Node *p = np; for (unsigned i = 0; i < n; i++) p->c[i] = c[i]; }
static void set_bounds(void *np, const struct RTCBounds **b, unsigned n, void *u) {
  Node *p = np; for (unsigned i = 0; i < n; i++) { p->b[i][0] = b[i]->lower_x; p->b[i][1] = b[i]->lower_y; p->b[i][2] = b[i]->lower_z; p->b[i][3] = b[i]->upper_x; p->b[i][4] = b[i]->upper_y; p->b[i][5] = b[i]->upper_z; } }
static void *create_leaf(RTCThreadLocalAllocator a, const struct RTCBuildPrimitive *pr, size_t n, void *u) {
  Leaf *l = rtcThreadLocalAlloc(a, sizeof(Leaf) + 4 * n, 16); l->leaf = 1; l->n = n; for (size_t i = 0; i < n; i++) l->id[i] = pr[i].primID; return l; }
static float *tv;
static int tri_hit(const double *o, const double *d, double t0, double t1, unsigned id) {
  const float *v = tv + 9 * (size_t)id;
  double e1[3], e2[3], p[3], q[3], s[3];
  for (int k = 0; k < 3; k++) { e1[k] = v[3 + k] - v[k]; e2[k] = v[6 + k] - v[k]; s[k] = o[k] - v[k]; }
  p[0] = d[1] * e2[2] - d[2] * e2[1]; p[1] = d[2] * e2[0] - d[0] * e2[2]; p[2] = d[0] * e2[1] - d[1] * e2[0];
  double det = e1[0] * p[0] + e1[1] * p[1] + e1[2] * p[2];
  if (det == 0) return 0;
  double inv = 1 / det, u = (s[0] * p[0] + s[1] * p[1] + s[2] * p[2]) * inv;
  if (u < 0 || u > 1) return 0;
  q[0] = s[1] * e1[2] - s[2] * e1[1]; q[1] = s[2] * e1[0] - s[0] * e1[2]; q[2] = s[0] * e1[1] - s[1] * e1[0];
  double w = (d[0] * q[0] + d[1] * q[1] + d[2] * q[2]) * inv;
  if (w < 0 || u + w > 1) return 0;
  double t = (e2[0] * q[0] + e2[1] * q[1] + e2[2] * q[2]) * inv;
  return t >= t0 && t <= t1;
}
static int box_hit(const double *o, const double *id, const float *b, double t0, double t1) {
  for (int a = 0; a < 3; a++) {
    double x0 = (b[a] - o[a]) * id[a], x1 = (b[a + 3] - o[a]) * id[a];
    if (x0 > x1) { double t = x0; x0 = x1; x1 = t; }
    if (x0 == x0 && x0 > t0) t0 = x0;
    if (x1 == x1 && x1 < t1) t1 = x1;
  }
  return t0 <= t1 * (1 + 1e-9);
}
int main(int argc, char **argv) {
  if (argc < 5) { fprintf(stderr, "usage: %s FILE BLOCK MINLEAF MAXLEAF\n", argv[0]); return 2; }
  FILE *f = fopen(argv[1], "rb"); unsigned nt, ns;
  if (!f) { perror(argv[1]); return 2; }
  if (fread(&nt, 4, 1, f) != 1 || !(tv = malloc(36 * (size_t)nt + 1)) || fread(tv, 36, nt, f) != nt) { fprintf(stderr, "truncated file: triangles\n"); return 2; }
  float *sg;
  if (fread(&ns, 4, 1, f) != 1 || !(sg = malloc(32 * (size_t)ns + 1)) || fread(sg, 32, ns, f) != ns) { fprintf(stderr, "truncated file: segments\n"); return 2; }
  fclose(f);
  RTCDevice dev = rtcNewDevice("threads=1");
  struct RTCBuildPrimitive *pr = malloc(sizeof(*pr) * nt);
  for (unsigned i = 0; i < nt; i++) {
    float *v = tv + 9 * (size_t)i; float lo[3], hi[3];
    for (int k = 0; k < 3; k++) { lo[k] = fminf(v[k], fminf(v[3 + k], v[6 + k])); hi[k] = fmaxf(v[k], fmaxf(v[3 + k], v[6 + k])); }
    pr[i] = (struct RTCBuildPrimitive){lo[0], lo[1], lo[2], 0, hi[0], hi[1], hi[2], i};
  }
  struct RTCBuildArguments a = rtcDefaultBuildArguments();
  a.maxBranchingFactor = 8; a.maxDepth = 1024; a.sahBlockSize = atoi(argv[2]); a.minLeafSize = atoi(argv[3]); a.maxLeafSize = atoi(argv[4]);
  a.bvh = rtcNewBVH(dev); a.primitives = pr; a.primitiveCount = nt; a.primitiveArrayCapacity = nt;
  a.createNode = create_node; a.setNodeChildren = set_children; a.setNodeBounds = set_bounds; a.createLeaf = create_leaf;
  void *root = rtcBuildBVH(&a);
  double inner = 0, leaves = 0, tris = 0; unsigned occ = 0;
  void *stack[4096];
  for (unsigned i = 0; i < ns; i++) {
    const float *s = sg + 8 * (size_t)i;
    double o[3] = {s[0], s[1], s[2]}, d[3] = {s[3], s[4], s[5]}, id[3];
    for (int k = 0; k < 3; k++) id[k] = 1.0 / d[k];
    double t0 = s[6], t1 = s[7]; int sp = 0, hit = 0;
    stack[sp++] = root;
    while (sp && !hit) {
      if (sp > 4096 - 8) { fprintf(stderr, "stack overflow\n"); return 1; }
      void *p = stack[--sp];
      if (((Node *)p)->leaf) {
        Leaf *l = p; leaves++;
        for (unsigned k = 0; k < l->n && !hit; k++) { tris++; hit = tri_hit(o, d, t0, t1, l->id[k]); }
        continue;
      }
      Node *n = p; inner++;
      for (int k = (int)n->n - 1; k >= 0; k--) if (box_hit(o, id, n->b[k], t0, t1)) stack[sp++] = n->c[k];
    }
    occ += hit;
  }
  printf("block %s minleaf %s maxleaf %s: inner %.2f leaves %.2f tris %.2f per ray, occluded %u of %u\n", argv[2], argv[3], argv[4], inner / ns, leaves / ns, tris / ns, occ, ns);
  return 0;
}
