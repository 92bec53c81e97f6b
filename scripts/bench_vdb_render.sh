#!/usr/bin/env bash
# Times `hytrace render` against OpenVDB's `vdb_render` on the same OpenVDB grid at the same
# image size (docs/bench-log.md, "Rendering on the CPU"). Needs Debian's python3-openvdb and
# libopenvdb-tools, and a release build (`cargo build --release --bin hytrace`).
#
# The grid: a 128^3 fog sphere (radius 60 voxels, blended over its outer 20, rippled),
# voxel size 1, written by pyopenvdb. Both renderers look at it from (0, 0, 200) down -z
# with y up, light from the same direction. vdb_render ray-marches (1 voxel steps, shadow
# rays every 3 voxels, single scattering); hytrace renders it by emission-absorption
# (march) and single scattering (delta tracking, ratio-tracked shadow rays).
set -euo pipefail
cd "$(dirname "$0")/.."
size=${1:-1280x720}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
/usr/bin/python3 - "$work/fog.vdb" <<'PY'
import sys
import numpy as np
import pyopenvdb as vdb

n = 128
x, y, z = np.meshgrid(*(np.arange(n) - 63.5,) * 3, indexing="ij")
r = np.sqrt(x * x + y * y + z * z)
ripple = 1.0 + 0.3 * np.sin(0.15 * x) * np.cos(0.11 * y) * np.sin(0.13 * z)
density = np.clip((60.0 - r) / 20.0, 0.0, 1.0) * ripple
grid = vdb.FloatGrid(0.0)
grid.copyFromArray(density.astype(np.float32), ijk=(-64, -64, -64), tolerance=0)
grid.name = "density"
grid.transform = vdb.createLinearTransform(voxelSize=1.0)
vdb.write(sys.argv[1], grids=[grid])
PY
cat > "$work/fog.toml" <<TOML
[volumes.fog]
source = "fog.vdb"
density_scale = 0.05
albedo = 0.9
emission = [0.8, 0.8, 0.8]

[camera]
eye = [0, 0, 200]
target = [0, 0, 0]
up = [0, 1, 0]
fov = 40

[[lights]]
kind = "directional"
direction = [-0.3, -0.3, -1]
irradiance = [3, 3, 3]
TOML
echo "machine: $(lscpu | sed -n 's/^Model name: *//p'), $(nproc) cores; date: $(date -u +%F); size $size"
seconds() { /usr/bin/time -f %e "$@" 2>&1 >/dev/null | tail -1; }
echo "vdb_render (-cpus 2, step 1 voxel, shadow step 3): $(seconds vdb_render "$work/fog.vdb" "$work/vdb.ppm" -res "$size" -cpus 2 -translate 0,0,200 -lookat 0,0,0 -up 0,1,0 -fov 40 -light 0.3,0.3,1 -absorb 0.005,0.005,0.005 -scatter 0.045,0.045,0.045) s"
for args in "--volumes emission-absorption --spp 1 --step 1" "--volumes emission-absorption --spp 1" "--volumes single-scattering --spp 1" "--volumes single-scattering --spp 16"; do
    # shellcheck disable=SC2086
    echo "hytrace render $args: $(seconds ./target/release/hytrace render "$work/fog.toml" --size "$size" $args -o "$work/ours.png") s"
done
