#!/usr/bin/env python3
"""Writes a weight blob whose networks reproduce the nominal CF2X model, for exercising the
firmware's learned-model path before trained weights exist:

    python3 tools/nominal_blob.py /tmp/nominal.hfw
    HAMFLIGHT_WEIGHTS=/tmp/nominal.hfw ./report.sh

Every hidden weight is zero, so each network outputs its last layer's bias: J^-1 = diag(1/J)
(J = 1.4e-5, 1.4e-5, 2.17e-5 kg m^2), g = the true input gain, W = a world force per unit of a
on each axis and a body torque of 1e-3 N m per unit of a about each axis. The cost of a control
step does not depend on the weights' values, so the step benchmark is representative.

Format: hamflight::blob (src/blob.rs): magic, version, shapes, body length, postcard body (every
f32 little-endian; a layer is its I*O weights row-major, then its O biases), CRC-32 of the body.
Shapes: hamflight::model (HIDDEN = 16; J^-1 9->6, g 9->24, W 15->36).
"""
import math
import struct
import sys
import zlib

H = 16
S_J, EPS = 1.0e5, 1.0e-2  # INERTIA_INV_SCALE_PER_KG_M2, INERTIA_INV_EPS (src/model/learned/mod.rs)


def mlp(i, o, out_bias):
    layers = [(i, H, [0.0] * H), (H, H, [0.0] * H), (H, o, out_bias)]
    return [v for (a, b, bias) in layers for v in [0.0] * (a * b) + bias]


def main(path):
    l = [math.sqrt(1.0 / j / S_J - EPS) for j in (1.4e-5, 1.4e-5, 2.17e-5)]
    inertia = mlp(9, 6, [l[0], 0.0, l[1], 0.0, 0.0, l[2]])  # [l11, l21, l22, l31, l32, l33]
    g = [0.0] * 24
    for row, col in ((2, 0), (3, 1), (4, 2), (5, 3)):  # body fz <- f, torques <- torques
        g[row * 4 + col] = 1.0
    w = [0.0] * 36
    for k in range(6):
        w[k * 6 + k] = 1.0
    body = b"".join(struct.pack("<f", v) for v in inertia + mlp(9, 24, g) + mlp(15, 36, w))
    header = b"HMFW" + struct.pack("<H", 1)
    header += b"".join(struct.pack("<3H", *s) for s in ((9, H, 6), (9, H, 24), (15, H, 36)))
    header += struct.pack("<I", len(body))
    with open(path, "wb") as f:
        f.write(header + body + struct.pack("<I", zlib.crc32(body) & 0xFFFFFFFF))


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit("usage: nominal_blob.py OUT.hfw")
    main(sys.argv[1])
