#!/usr/bin/env bash
# Install everything diffuse-imaging and its tests need on a fresh Debian/Ubuntu machine. Idempotent.
#
# Dr.Jit's LLVM backend (the renderer's CPU path) aborts with the system's
# LLVM 15 ("Cannot select: fmaximum"); LLVM 19 from Debian works, so it is
# installed unless an LLVM >= 16 is already there. transient/backend.py
# finds it at run time and refuses, in one line, to run on LLVM <= 15.
set -euo pipefail
cd "$(dirname "$0")/.."
started=$SECONDS

if ! ldconfig -p 2>/dev/null | grep -Eq 'libLLVM(-(1[6-9]|[2-9][0-9])\.so|\.so\.(1[6-9]|[2-9][0-9]))'; then
    sudo=""
    if [ "$(id -u)" -ne 0 ]; then sudo="sudo"; fi
    $sudo apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq libllvm19 >/dev/null
fi
python3 -m pip install --quiet --disable-pip-version-check --root-user-action=ignore -e ".[test]"
# pip compiles a regular install's modules, not an editable one's: compile them here, so that commands
# do not recompile them at every start where PYTHONDONTWRITEBYTECODE is set
python3 -m compileall -q analytic transient validation interop
installed=$SECONDS
# A command compiles the model's kernels that its scene needs on their first use (seconds for the
# built-in scene) and the renderer's on its first render; the tests need every route. Both are compiled
# and cached here (analytic/kernels/__pycache__, ~/.drjit), each in its own process, while tal's
# environment installs beside them.
python3 scripts/warm_kernels.py --waveform impulse &
steps=$!
python3 scripts/warm_kernels.py --waveform square &
moments=$!
python3 scripts/warm_kernels.py --renderer &
renderer=$!
trap 'kill "$steps" "$moments" "$renderer" 2>/dev/null || true' EXIT   # a failed step leaves no compile running
# tal (y-tal) pins numpy < 2: it gets its own environment, used by the tests that read our HDF5 with it
bash scripts/setup_interop.sh
wait "$steps"
wait "$moments"
wait "$renderer"
trap - EXIT
echo "diffuse-imaging: set-up done in $((SECONDS - started)) s (install $((installed - started)) s, then tal and the warm-up $((SECONDS - installed)) s)" >&2
