#!/usr/bin/python3
# A smoke-like OpenVDB grid for media from grids (README, "Media from OpenVDB grids"): a puff, a sphere of radius 0.8
# whose density falls off towards its edge, carved by a warped sum of sines at three octaves (0 where the sum cuts it
# away), on N^3 voxels spanning [0, 1]^3, as the float grid "density". Needs Debian's python3-openvdb (run with the
# system's Python, whose module it is). examples/smoke/smoke.vdb is `bench/smoke_vdb.py examples/smoke/smoke.vdb 48`.
#   /usr/bin/python3 bench/smoke_vdb.py OUT.vdb [N]
import sys

import numpy as np
import pyopenvdb as vdb

path, n = sys.argv[1], int(sys.argv[2]) if len(sys.argv) > 2 else 128
x = (np.arange(n) + 0.5) / n * 2 - 1  # voxel centres over [-1, 1]
X, Y, Z = np.meshgrid(x, x, x, indexing="ij")
r = np.sqrt(X**2 + Y**2 + Z**2)
noise = sum(np.sin(f * X + 1.7 * k + 2 * np.sin(f * Y)) * np.sin(f * Y + 2.3 * k + 2 * np.sin(f * Z)) *
            np.sin(f * Z + 0.9 * k + 2 * np.sin(f * X)) / f for k, f in enumerate((4.0, 9.0, 19.0)))
density = np.clip((0.8 - r) / 0.3, 0, 1) * np.clip(0.1 + 4 * noise, 0, None)
grid = vdb.FloatGrid()
grid.copyFromArray(density.astype(np.float32), tolerance=1e-4)
grid.name = "density"
grid.transform = vdb.createLinearTransform(voxelSize=1.0 / n)  # the grid spans [0, 1]^3
vdb.write(path, grids=[grid])
