"""Debian's python3-openvdb (module pyopenvdb) reads a vdbclay file: Tc from the density grid's
metadata, and the exact mass back as round(density * Tc), equal to the run's mass_final.

Usage: openvdb_reads_clay.py VDBCLAY_CLI WORKDIR. Exits 77 (ctest: skipped) without pyopenvdb.
"""
import json
import os
import subprocess
import sys

try:
    import pyopenvdb as vdb
except ImportError:
    print("SKIP: pyopenvdb (Debian: python3-openvdb) is not installed")
    sys.exit(77)

cli, work = sys.argv[1], sys.argv[2]
os.makedirs(work, exist_ok=True)
out, stats = os.path.join(work, "clay.vdb"), os.path.join(work, "clay.json")
scene = os.path.join(work, "tc250.json")
with open(scene, "w") as f:
    json.dump({"threshold": 250, "voxel_size": 0.25,
               "clay": [{"shape": "box", "min": [0, 0, 0], "max": [11, 11, 11], "mass": 250}],
               "tools": [{"shape": "box", "min": [-4, 10, -4], "max": [15, 16, 15],
                          "path": [{"translate": [0, -1, 0], "frames": 2}]}]}, f)
subprocess.run([cli, "run", scene, "-o", out, "--stats", stats, "--quiet"], check=True,
               stdout=subprocess.DEVNULL)
with open(stats) as f:
    mass_final = json.load(f)["mass_final"]

# The Int32 "mass" grid is what this module cannot read (readAllGridMetadata fails on the file
# too); "density" it reads by name, with the metadata.
density = vdb.read(out, "density")
tc = density.metadata["vdbclay_threshold"]
assert tc == 250, tc
assert density.metadata["vdbclay_rule"] == "prorata"
assert abs(density.metadata["vdbclay_voxel_size"] - 0.25) < 1e-12
assert abs(density.transform.voxelSize()[0] - 0.25) < 1e-12
total = sum(int(round(v.value * tc)) * v.count for v in density.citerOnValues())
assert total == mass_final, (total, mass_final)
print(f"pyopenvdb: Tc {tc}, mass from density {total} == mass_final {mass_final}: OK")
