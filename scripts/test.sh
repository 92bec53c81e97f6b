#!/usr/bin/env bash
# Runs every check and test of hytrace, installing what cargo cannot:
#  - Mesa's lavapipe Vulkan driver (Debian: mesa-vulkan-drivers, libvulkan1), so GPU tests
#    run on machines without a GPU;
#  - the OpenVDB/NanoVDB references (Debian: python3-openvdb for /usr/bin/python3,
#    libnanovdb-tools, libopenvdb-tools), oracles of the volume tests;
#  - Embree 3 (Debian: libembree-dev), which the `embree` feature's backend links;
#  - the Python oracle environment (.venv, from tests/requirements.txt), into which the
#    Python package (crates/python) is built and installed, then tested against the command.
# GPU and oracle tests fail (not skip) when their dependencies are missing.
set -euo pipefail
cd "$(dirname "$0")/.."

apt_packages=(mesa-vulkan-drivers libvulkan1 python3-openvdb libnanovdb-tools libopenvdb-tools libembree-dev)
missing=()
for p in "${apt_packages[@]}"; do
  dpkg -s "$p" >/dev/null 2>&1 || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  if [ "$(id -u)" = 0 ]; then
    echo "installing ${missing[*]} (Debian)"
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${missing[@]}" >/dev/null
  elif command -v sudo >/dev/null; then
    sudo apt-get update -qq
    sudo DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${missing[@]}" >/dev/null
  else
    echo "error: install ${missing[*]} (Debian packages) as root, then run $0 again" >&2
    exit 1
  fi
fi

venv=.venv
stamp=$venv/.requirements
if [ ! -x "$venv/bin/python" ] || ! cmp -s tests/requirements.txt "$stamp"; then
  echo "creating the Python oracle environment in $venv"
  python3 -m venv "$venv"
  "$venv/bin/python" -m pip install -q --upgrade pip
  "$venv/bin/python" -m pip install -q -r tests/requirements.txt
  cp tests/requirements.txt "$stamp"
fi

export HYTRACE_PYTHON="$PWD/$venv/bin/python"
export HYTRACE_REQUIRE_ORACLES=1
# Debian's interpreter, which has pyopenvdb (python3-openvdb) and NumPy.
export HYTRACE_VDB_PYTHON="${HYTRACE_VDB_PYTHON:-/usr/bin/python3}"
export HYTRACE_REQUIRE_GPU="${HYTRACE_REQUIRE_GPU:-1}"
# GPU tests run on Vulkan (lavapipe without a GPU), not on a GL fallback.
export WGPU_BACKEND="${WGPU_BACKEND:-vulkan}"
# Mesa's window-system probing complains without it; compute needs no display.
export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-$(mktemp -d)}"

cargo fmt --all -- --check
cargo clippy --workspace --all-targets -- -D warnings
# Includes crates/trace/tests/readme_quickstarts.rs: the README's quickstarts, run as written.
cargo test --workspace
# The API documentation builds without warnings (broken or private intra-doc links).
RUSTDOCFLAGS="-D warnings" cargo doc --workspace --no-deps
# Relative links and #anchors of README.md, BENCHMARKS.md and docs/.
python3 scripts/check_doc_links.py
# The Embree backend (`--backend embree`): its own build of the tracer crate.
cargo clippy -p hytrace-trace --features embree --all-targets -- -D warnings
cargo test -p hytrace-trace --features embree
# The Python package: installed into .venv as users install it (a release build, the
# command line's release build beside it), then its tests compare every function with
# the command bit for bit and run hytrace.dask on LocalClusters.
cargo build --release -p hytrace-trace --bin hytrace
# (maturin's build backend runs `maturin`, found on PATH.)
PATH="$PWD/$venv/bin:$PATH" "$venv/bin/python" -m pip install -q --no-build-isolation \
  --force-reinstall --no-deps ./crates/python
HYTRACE_BIN="$PWD/target/release/hytrace" "$venv/bin/python" -m pytest -q crates/python/tests
