#!/usr/bin/python3
"""Writes data/sample_rig/: a small blendshape OBJ folder in the form crease imports
(`crease rig import --objs data/sample_rig --units cm`). It exercises the importer
the way a real rig does: quads, per-corner UVs with a seam down the middle (the
centre column carries two UVs), centimetres, named expressions, identity modes and
a landmarks.json with the 68 iBUG landmarks. The shape is a stylised face mask, not
a person; the synthetic studio (synth/) builds the realistic rig.

Run with Debian's python (numpy): /usr/bin/python3 scripts/make_sample_rig.py
"""
import json
import os
import numpy as np

NS, NT = 40, 52  # quads across (s) and down (t)
W, H, D = 15.0, 20.0, 8.0  # cm
out = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "data", "sample_rig")


def g(s, t, cs, ct, rs, rt):
    return np.exp(-(((s - cs) / rs) ** 2 + ((t - ct) / rt) ** 2))


s, t = np.meshgrid(np.linspace(0, 1, NS + 1), np.linspace(0, 1, NT + 1))
s, t = s.ravel(), t.ravel()


def face(id_coef):
    w = W * (1 + 0.08 * id_coef[0])
    h = H * (1 + 0.06 * id_coef[1])
    x = (s - 0.5) * w
    y = -(t - 0.5) * h
    r2 = np.clip((2 * (s - 0.5)) ** 2 * 0.85 + (2 * (t - 0.5)) ** 2 * 0.6, 0, 1)
    z = D * np.sqrt(1 - r2)
    z += (1.6 + 0.4 * id_coef[2]) * g(s, t, 0.5, 0.52, 0.05, 0.12)  # nose
    z -= 0.9 * (g(s, t, 0.33, 0.40, 0.08, 0.04) + g(s, t, 0.67, 0.40, 0.08, 0.04))  # eye sockets
    z += 0.4 * g(s, t, 0.5, 0.75, 0.12, 0.04)  # lips
    z += 0.3 * id_coef[3] * g(s, t, 0.5, 0.92, 0.1, 0.06)  # chin
    return np.stack([x, y, z], axis=1)


def expression(name, base):
    d = np.zeros_like(base)
    if name == "jawOpen":
        m = np.clip((t - 0.74) / 0.1, 0, 1) * np.exp(-((s - 0.5) / 0.3) ** 2)
        d[:, 1] -= 2.0 * m
        d[:, 2] -= 0.6 * m
    elif name == "browInnerUp":
        d[:, 1] += 0.5 * (g(s, t, 0.4, 0.3, 0.07, 0.06) + g(s, t, 0.6, 0.3, 0.07, 0.06))
    elif name in ("mouthSmile_L", "mouthSmile_R"):
        cs = 0.6 if name.endswith("_L") else 0.4
        m = g(s, t, cs, 0.74, 0.07, 0.05)
        d[:, 0] += 0.5 * m * np.sign(cs - 0.5)
        d[:, 1] += 0.4 * m
    elif name in ("eyeBlink_L", "eyeBlink_R"):
        cs = 0.67 if name.endswith("_L") else 0.33
        d[:, 1] -= 0.5 * g(s, t, cs, 0.385, 0.06, 0.02)
    elif name == "browDown":
        d[:, 1] -= 0.4 * (g(s, t, 0.42, 0.32, 0.08, 0.05) + g(s, t, 0.58, 0.32, 0.08, 0.05))
        d[:, 0] += 0.2 * (g(s, t, 0.42, 0.32, 0.06, 0.05) - g(s, t, 0.58, 0.32, 0.06, 0.05))
    return base + d


def write_obj(path, V):
    vid = lambda i, j: j * (NS + 1) + i
    # UVs: the left half maps to u in [0, 0.49], the right half to [0.51, 1]; the
    # centre column carries both, so it is split along a seam on import.
    uvs, uv_index = [], {}
    for j in range(NT + 1):
        for i in range(NS + 1):
            for side in ((0, 1) if i == NS // 2 else ((0,) if i < NS // 2 else (1,))):
                u = (i / NS) * 0.98 if side == 0 else 0.51 + (i / NS - 0.5) * 0.98
                uv_index[(i, j, side)] = len(uvs)
                uvs.append((u, t[vid(i, j)]))
    with open(path, "w") as f:
        f.write("# crease sample rig shape, cm\n")
        for p in V:
            f.write("v %.6f %.6f %.6f\n" % tuple(p))
        for u, v in uvs:
            f.write("vt %.6f %.6f\n" % (u, 1.0 - v))  # OBJ v grows upwards
        for j in range(NT):
            for i in range(NS):
                side = 0 if i < NS // 2 else 1
                c = [(i, j), (i, j + 1), (i + 1, j + 1), (i + 1, j)]
                f.write("f " + " ".join("%d/%d" % (vid(a, b) + 1, uv_index[(a, b, side)] + 1) for a, b in c) + "\n")


def ibug68():
    p = []
    for k in range(17):  # jaw, 1..17
        a = np.pi * (1 - k / 16)
        p.append((0.5 + 0.4 * np.cos(a), 0.45 + 0.47 * np.sin(a)))
    for k in range(5):  # right brow (image left), 18..22
        p.append((0.22 + 0.055 * k, 0.33 - 0.03 * np.sin(np.pi * k / 4)))
    for k in range(5):  # left brow, 23..27
        p.append((0.56 + 0.055 * k, 0.33 - 0.03 * np.sin(np.pi * k / 4)))
    for k in range(4):  # nose bridge, 28..31
        p.append((0.5, 0.40 + 0.06 * k))
    for k in range(5):  # nose bottom, 32..36
        p.append((0.44 + 0.03 * k, 0.6 + 0.015 * np.sin(np.pi * k / 4)))
    # Eyes 37..42 (subject's right: outer corner first) and 43..48 (subject's left:
    # inner corner first); both start at the image-left corner and go over the top.
    for cx in (0.33, 0.67):
        for a in (np.pi, 2 * np.pi / 3, np.pi / 3, 0, -np.pi / 3, -2 * np.pi / 3):
            p.append((cx + 0.06 * np.cos(a), 0.40 - 0.02 * np.sin(a)))
    for k in range(12):  # outer lip, 49..60
        a = np.pi - 2 * np.pi * k / 12
        p.append((0.5 + 0.1 * np.cos(a), 0.75 - 0.04 * np.sin(a)))
    for k in range(8):  # inner lip, 61..68
        a = np.pi - 2 * np.pi * k / 8
        p.append((0.5 + 0.07 * np.cos(a), 0.75 - 0.015 * np.sin(a)))
    ids = []
    for ps, pt in p:
        ids.append(int(np.argmin((s - ps) ** 2 + (t - pt) ** 2)))
    return ids


os.makedirs(os.path.join(out, "identity"), exist_ok=True)
os.makedirs(os.path.join(out, "expressions"), exist_ok=True)
base = face([0, 0, 0, 0])
write_obj(os.path.join(out, "neutral.obj"), base)
for k in range(4):
    c = [0, 0, 0, 0]
    c[k] = 1
    write_obj(os.path.join(out, "identity", "identity%03d.obj" % k), face(c))
for name in ["jawOpen", "browInnerUp", "browDown", "mouthSmile_L", "mouthSmile_R", "eyeBlink_L", "eyeBlink_R"]:
    write_obj(os.path.join(out, "expressions", name + ".obj"), expression(name, base))
with open(os.path.join(out, "landmarks.json"), "w") as f:
    json.dump(ibug68(), f)
print("wrote", os.path.normpath(out))
