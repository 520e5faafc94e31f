#!/usr/bin/env python3
"""Sculpts a ball of clay with a capsule tool, frame by frame, and writes the result as a .vdb.

    PYTHONPATH=build/python /usr/bin/python3 python/examples/sculpt.py out.vdb

The .vdb opens in Blender (File > Import > OpenVDB; the "density" grid), Houdini or vdb_view.
"""
import sys

import numpy as np
import vdbclay

out = sys.argv[1] if len(sys.argv) > 1 else "sculpt.vdb"

# A ball of clay, full cells (mass = Tc = 1000 per voxel), voxel size 0.05 world units.
clay = vdbclay.make_clay(vdbclay.sphere((0, 0, 0), 12), mass=1000, voxel_size=0.05)
automaton = vdbclay.Automaton(clay, rule="prorata")
start_mass = clay.total_mass()
print(f"start: {clay.voxel_count()} voxels, mass {start_mass}")

# A finger (capsule) presses into the top of the ball, 1 voxel per frame, and clay settles.
finger = vdbclay.capsule((0, 10, 0), (0, 30, 0), radius=4)
for frame in range(6):
    tool = finger.moved(translate=(0, -2 * frame, 0))
    pushed = automaton.push([tool])
    report = automaton.settle(max_steps=20000)
    print(f"frame {frame + 1}: pushed {pushed['mass_moved']} clay, "
          f"{report['steps']} steps, settled {report['settled']}")

# A lump added from numpy: a 4^3 block of overloaded clay on the side, which then spreads.
automaton.add_mass(np.full((4, 4, 4), 3000, dtype=np.int32), origin=(12, -2, -2))
automaton.settle(max_steps=20000)

clay = automaton.clay
density = clay.density_array()
assert clay.total_mass() == start_mass + 64 * 3000  # mass is exact: pushed and settled, never lost
print(f"end: {clay.voxel_count()} voxels, mass {clay.total_mass()}, "
      f"max density {density.max():.3f}, box {density.shape}")
clay.write(out)
print(f"wrote {out}")
