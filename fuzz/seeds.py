#!/usr/bin/env python3
"""Build fuzz/work/<target>/ seed inputs: the shared scenes' files cut small, plus small files that
`hirad` itself writes (built-in scenes, a coarse solution, 8x6 images). Usage (from the repo root,
after `cargo build --release -p hirad-cli`): python3 fuzz/seeds.py"""
import json, os, struct, subprocess, sys, tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SHARED = os.path.join(ROOT, "..", "shared", "scenes")
OUT = os.path.join(ROOT, "fuzz", "work")
HIRAD = os.path.join(ROOT, "target", "release", "hirad")
SEP = b"\n@@@ "


def put(target, name, *parts):
    """parts: main bytes, then (filename, bytes) pairs."""
    d = os.path.join(OUT, target)
    os.makedirs(d, exist_ok=True)
    data = parts[0]
    for fname, body in parts[1:]:
        data += SEP + fname.encode() + b"\n" + body
    open(os.path.join(d, "seed-" + name), "wb").write(data)


def read(p):
    return open(p, "rb").read()


def cut_obj(text, nv=40, nf=40):
    """First nv vertices and the first nf faces using only them, keeping other statements."""
    out, v, f = [], 0, 0
    for line in text.splitlines():
        w = line.split()
        if not w:
            continue
        if w[0] == "v":
            if v < nv:
                v += 1
                out.append(line)
        elif w[0] == "f":
            idx = [int(c.split("/")[0]) for c in w[1:]]
            if f < nf and all(0 < i <= nv for i in idx):
                f += 1
                out.append(line)
        elif w[0] in ("vn", "vt"):
            continue
        elif len(out) < 400:
            out.append(line)
        if f >= nf:
            break
    return ("\n".join(out) + "\n").encode()


def cut_stmts(text, limit):
    """First statements of a text file, cut at a line boundary below `limit` bytes."""
    b = text[:limit]
    return b[: b.rfind(b"\n") + 1] if b"\n" in b else b


tmp = tempfile.mkdtemp()
run = lambda *a: subprocess.run([HIRAD, "-q", *a], cwd=tmp, check=True, capture_output=True)
run("scene", "cornell", "--out", "cornell.obj")
run("scene", "cornell", "--out", "cornell.glb")
run("scene", "furnace", "--out", "furnace.glb")
run("scene", "cornell", "--out", "ct.toml")
run("solve", "cornell", "--out", "sol", "--min-area-rel", "0.5", "--max-iters", "1")
run("render", "sol/solution.glb", "--size", "8x6", "--image", "im.exr")
run("render", "sol/solution.glb", "--size", "8x6", "--image", "im.png")
T = lambda n: read(os.path.join(tmp, n))

# OBJ + MTL: the built-in cornell box, and each shared OBJ cut to 40 vertices with its MTL.
put("obj", "cornell", T("cornell.obj").replace(b"mtllib cornell.mtl", b"mtllib a.mtl"), ("a.mtl", T("cornell.mtl")))
for s in sorted(os.listdir(SHARED)):
    o = os.path.join(SHARED, s, s + ".obj")
    if os.path.exists(o):
        head = read(o).decode("utf-8", "replace")
        body = cut_obj(head).replace(f"mtllib {s}.mtl".encode(), b"mtllib a.mtl")
        put("obj", s, body, ("a.mtl", cut_stmts(read(os.path.join(SHARED, s, s + ".mtl")), 1500)))
put("obj", "quad", b"# +Z up.\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvn 0 0 1\ng a\nf 1/1/1 2/1/1 3/1/1 -1/1/1\no b\nf -4//1 -3//1 -2//1\n")
put("obj", "tobj", b"v 0 0 0 \\\n\nv 1 0 0\nv 0 1 0\ncurv 0 1 1 2\nf 1 2 3\n")

# glTF/GLB: built-in scenes as GLB, cornell as .gltf with an external and with an embedded buffer.
for n in ("cornell", "furnace"):
    put("gltf", n + ".glb", T(n + ".glb"))
glb = T("cornell.glb")
jlen = struct.unpack_from("<I", glb, 12)[0]
doc = json.loads(glb[20 : 20 + jlen])
binchunk = glb[20 + jlen + 8 :]
doc["buffers"][0]["uri"] = "a.bin"
put("gltf", "cornell.gltf", json.dumps(doc).encode(), ("a.bin", binchunk))
import base64
doc["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(binchunk).decode()
put("gltf", "embedded.gltf", json.dumps(doc).encode())

# PLY: a coarse solution (binary) and hand-made ASCII and big-endian quads.
put("ply", "solution", T("sol/solution.ply"))
put("ply", "ascii", b"ply\nformat ascii 1.0\ncomment +Z up\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0 255 0 0\n1 0 0 0 255 0\n1 1 0 0 0 255\n0 1 0 9 9 9\n4 0 1 2 3\n")
be = b"ply\nformat binary_big_endian 1.0\nelement vertex 3\nproperty double x\nproperty double y\nproperty double z\nelement face 1\nproperty list uchar uint vertex_indices\nend_header\n"
be += b"".join(struct.pack(">ddd", *p) for p in ((0, 0, 0), (1, 0, 0), (0, 1, 0))) + struct.pack(">BIII", 3, 0, 1, 2)
put("ply", "be", be)

# TOML: descriptions naming OBJ, PLY, glTF and MGF files, and the repo's scenes/*.toml.
ct = T("ct.toml").replace(b"ct.obj", b"a.obj")
put("toml", "cornell", ct, ("a.obj", T("ct.obj").replace(b"mtllib ct.mtl", b"mtllib a.mtl")), ("a.mtl", T("ct.mtl")))
put("toml", "ply", b'up = "z"\n[[mesh]]\nfile = "a.ply"\nscale = [1, 2, 1]\nrotate = [0, 90, 0]\n[[light]]\ncorner = [0, 0, 1]\nedge1 = [1, 0, 0]\nedge2 = [0, 1, 0]\nradiance = [1, 1, 1]\n[sun]\ndirection = [0, 0, -1]\nirradiance = [1, 1, 1]\n', ("a.ply", read(os.path.join(OUT, "ply", "seed-ascii"))))
put("toml", "mgf", b'sky = [0.1, 0.1, 0.1]\n[[mesh]]\nfile = "a.mgf"\ntranslate = [1, 0, 0]\n[[mesh]]\nfile = "b.glb"\n[materials.white]\nrho = [0.5, 0.5, 0.5]\nemission = [0, 0, 0]\n', ("a.mgf", cut_stmts(read(os.path.join(SHARED, "mgf", "cube.mgf")), 3000)), ("b.glb", T("furnace.glb")))
for s in sorted(os.listdir(os.path.join(ROOT, "scenes"))):
    put("toml", s, read(os.path.join(ROOT, "scenes", s)))

# MGF: every shared file cut to 3 kB; include chains (materials, hospital parts) as extra files.
mgfdir = os.path.join(SHARED, "mgf")


def flat_includes(dp, body):
    """Point `i path` lines at extra files (flat names) holding the first 2 kB of each."""
    extra, lines = [], []
    for line in body.split(b"\n"):
        w = line.split()
        if len(w) >= 2 and w[0] == b"i":
            src = os.path.normpath(os.path.join(dp, w[1].decode()))
            name = os.path.basename(src)
            if os.path.exists(src) and all(n != name for n, _ in extra):
                extra.append((name, cut_stmts(read(src), 2000)))
            line = b" ".join([b"i", name.encode()] + w[2:])
        lines.append(line)
    return b"\n".join(lines), extra


for dp, _, fs in os.walk(mgfdir):
    for f in sorted(fs):
        if f.endswith(".mgf"):
            rel = os.path.relpath(os.path.join(dp, f), mgfdir).replace("/", "_")
            body, extra = flat_includes(dp, cut_stmts(read(os.path.join(dp, f)), 3000))
            put("mgf", rel, body, *extra)
mats = cut_stmts(read(os.path.join(mgfdir, "Materials", "dupont.mgf")), 1500)
put("mgf", "include", b"i a.mgf\ni b.mgf -t 0 0 1 -s 2\nm\nv p0 =\n p 0 0 0\nv p1 =\n p 1 0 0\nv p2 =\n p 0 1 0\nf p0 p1 p2\n", ("a.mgf", mats), ("b.mgf", cut_stmts(read(os.path.join(mgfdir, "hospital", "mug.mgf")), 2000)))
put("mgf", "xfarray", b"xf -a 3 -t 1 0 0 -a 2 -rz 90\nsph c 0.1\nxf\nv c =\n p 0 0 0\n n 0 0 1\ncyl c 1 c\n")

# Images as `hirad diff` reads them; solutions as `hirad render` reads them.
put("image", "exr", T("im.exr"))
put("image", "png", T("im.png"))
put("solution", "solution", T("sol/solution.glb"))
put("solution", "cornell", T("cornell.glb"))
for t in sorted(d for d in os.listdir(OUT) if os.path.isdir(os.path.join(OUT, d))):
    fs = os.listdir(os.path.join(OUT, t))
    print(t, len(fs), sum(os.path.getsize(os.path.join(OUT, t, f)) for f in fs), "bytes")
