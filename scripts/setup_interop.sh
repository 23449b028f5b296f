#!/usr/bin/env bash
# The interoperability extras: tal (y-tal) in its own virtual environment. Idempotent.
#
# y-tal pins numpy<2 (through nptyping) and Pillow==10.3.0, which would
# downgrade the project's own environment, so it lives in .venv-tal at the
# repository root (ignored by git). The tests that read our HDF5 captures
# back with tal.io.read_capture run .venv-tal/bin/python in a subprocess and
# are skipped, saying why, when it is absent. mitransient installs into the
# main environment (the `bench` extra) and needs nothing here.
#
# With --render it also makes .venv-tal-render: y-tal 0.20.0 with the
# renderer it drives (mitsuba 3.9.1, mitransient 1.3.1), for `tal render`
# round trips (docs/tal.md; the slow tests that use it skip without it).
set -euo pipefail
cd "$(dirname "$0")/.."

venv=.venv-tal
if [ ! -x "$venv/bin/python" ]; then
    python3 -m venv "$venv"
fi
if ! "$venv/bin/python" -c "import tal, h5py" >/dev/null 2>&1; then
    # pip's notes on this machine's local indexes go to a log, shown only if the install fails
    log=$(mktemp)
    "$venv/bin/python" -m pip install --quiet --disable-pip-version-check y-tal h5py 2>"$log" \
        || { cat "$log" >&2; rm -f "$log"; exit 1; }
    rm -f "$log"
fi
"$venv/bin/python" -c "import tal, h5py"

if [ "${1:-}" = "--render" ]; then
    render=.venv-tal-render
    if [ ! -x "$render/bin/python" ]; then
        python3 -m venv "$render"
    fi
    if ! "$render/bin/python" -c "import tal, mitsuba, h5py, importlib.util as u; assert u.find_spec('mitransient')" >/dev/null 2>&1; then
        log=$(mktemp)
        "$render/bin/python" -m pip install --quiet --disable-pip-version-check y-tal==0.20.0 mitsuba==3.9.1 \
            mitransient==1.3.1 h5py 2>"$log" || { cat "$log" >&2; rm -f "$log"; exit 1; }
        rm -f "$log"
    fi
    "$render/bin/python" -c "import tal, mitsuba, h5py, importlib.util as u; assert u.find_spec('mitransient')"
fi
