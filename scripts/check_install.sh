#!/usr/bin/env bash
# A user's install, checked: `pip install .` (not editable) of this working tree into a fresh
# virtual environment, then, from a folder outside the tree, the three commands the README
# promises: `fit-params --demo`, `jsss-render` on a shipped example and `jsss materials`
# (`jsss table` where this checkout has no `materials` subcommand yet). Every data file must
# ship: the transport tables, the calibration table and the examples (jsss/examples in the
# installed package; `pip install .` builds them from examples/ through pyproject.toml).
#
#   scripts/check_install.sh            # about 2-4 min, most of it pip; not part of the test suite
#   KEEP=1 scripts/check_install.sh     # keep the venv and the folder it ran in
#
# It copies the files git would commit (tracked, plus untracked ones not ignored), so build
# folders and caches of this checkout do not leak into the install.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
work="$(mktemp -d -t jsss-check-install-XXXXXX)"
[ "${KEEP:-0}" = 1 ] || trap 'rm -rf "$work"' EXIT
export PIP_DISABLE_PIP_VERSION_CHECK=1 JSSS_CACHE_DIR="$work/cache"
unset JAX_COMPILATION_CACHE_DIR PYTHONPATH

step() { printf '\n== %s (%s)\n' "$1" "$(date +%T)"; }

step "copy the tree"
mkdir "$work/src" "$work/elsewhere"
(cd "$root" && git ls-files -co --exclude-standard -z | xargs -0 tar -cf - 2>/dev/null) | tar -xf - -C "$work/src"

step "fresh venv, pip install . (not editable)"
python3 -m venv "$work/venv"
# shellcheck disable=SC1091
. "$work/venv/bin/activate"
start=$SECONDS
pip install -q "$work/src"
echo "pip install: $((SECONDS - start)) s, site-packages $(du -sm "$work/venv/lib" | cut -f1) MB"
rm -rf "$work/src"   # nothing may be read from the source tree after this

cd "$work/elsewhere"
python - <<'EOF'
import pathlib, jsss
here = pathlib.Path(jsss.__file__).resolve()
assert "site-packages" in here.parts, f"jsss imported from {here}, not from the install"
examples = here.parent / "examples"
for name in ("marble_sphere.toml", "head.toml", "head/head.obj", "maps/studio.exr"):
    assert (examples / name).is_file(), f"{name} did not ship"
print("jsss from", here.parent, "; examples:", ", ".join(sorted(p.name for p in examples.glob("*.toml"))))
EOF
examples="$(python -c 'import jsss, pathlib; print(pathlib.Path(jsss.__file__).parent / "examples")')"

step "fit-params --demo"
fit-params --demo

step "jsss-render <a shipped example>"
jsss-render "$examples/marble_sphere.toml" -o marble.png
test -s marble.png && test -s marble.exr && echo "wrote marble.png and marble.exr"
jsss-render "$examples/checker_plane.toml" -o checker.png   # a scene that reads an EXR map beside it
test -s checker.png && echo "wrote checker.png"

if jsss materials --help >/dev/null 2>&1; then
    step "jsss materials"
    jsss materials | tail -5
else
    step "jsss table (this checkout has no 'jsss materials' yet)"
    jsss table | tail -5
fi
step "all commands ran from $(pwd)"
