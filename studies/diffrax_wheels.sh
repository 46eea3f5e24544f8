#!/usr/bin/env bash
# Downloads the pure-Python wheels that studies/baseline_diffrax.py needs on top of jax/jaxlib
# (diffrax and its dependencies, for Python 3.12) into .diffrax_wheels/ at the repository root, and
# writes .diffrax_wheels/install.sh, which installs them without a package index:
#
#   bash studies/diffrax_wheels.sh                  # here, with internet
#   bash .diffrax_wheels/install.sh [/tmp/site]     # on the GPU host (has jax+jaxlib with CUDA)
#   export PYTHONPATH=/tmp/site:$PWD
#
# jax and jaxlib are NOT downloaded: the host's own CUDA build is used. The pins work with
# jax >= 0.6.1 except 0.7.0/0.7.1 (equinox excludes those; lineax 0.1.0 needs >= 0.6.1; lineax
# 0.1.1 would need jax >= 0.10, hence 0.1.0). Dependency lists (Requires-Dist, extras dropped):
#   diffrax 0.7.2:     equinox>=0.11.10 jax>=0.4.38 jaxtyping>=0.2.24 lineax>=0.0.5
#                      optimistix>=0.1.0 typing-extensions>=4.5.0 wadler-lindig>=0.1.1
#   equinox 0.13.8:    jax!=0.7.0,!=0.7.1,>=0.4.38 jaxtyping>=0.2.20 typing-extensions>=4.5.0
#                      wadler-lindig>=0.1.0
#   lineax 0.1.0:      equinox>=0.11.10 jax>=0.6.1 jaxtyping>=0.2.24 typing-extensions>=4.5.0
#   optimistix 0.1.0:  equinox>=0.11.11 jax!=0.7.0,!=0.7.1,>=0.4.38 jaxtyping>=0.2.24
#                      lineax>=0.0.6 typing-extensions>=4.5.0
#   jaxtyping 0.3.11:  wadler-lindig>=0.1.3   (no typeguard since jaxtyping 0.3)
#   wadler-lindig 0.1.8, typing-extensions 4.15.0: none
set -euo pipefail
cd "$(dirname "$0")/.."
DEST=.diffrax_wheels
PINS=(diffrax==0.7.2 equinox==0.13.8 lineax==0.1.0 optimistix==0.1.0 jaxtyping==0.3.11
      wadler-lindig==0.1.8 typing-extensions==4.15.0)
rm -rf "$DEST" && mkdir -p "$DEST"
# --no-deps: the list above is the complete closure minus jax/jaxlib/numpy (checked by the import
# test of install.sh); --python-version 3.12 --only-binary: wheels for the GPU host's Python
python3 -m pip download --no-deps --only-binary=:all: --python-version 3.12 --implementation py \
    -d "$DEST" "${PINS[@]}"
cat > "$DEST/install.sh" <<'EOF'
#!/usr/bin/env bash
# Installs the wheels beside this script into a target folder (default /tmp/site), no index, no
# dependency resolution (jax/jaxlib/numpy come from the host). Then: export PYTHONPATH=/tmp/site:$PWD
set -euo pipefail
HERE="$(cd "$(dirname "$0")" && pwd)"
TARGET="${1:-/tmp/site}"
mkdir -p "$TARGET"
python3 -m pip install --no-index --no-deps --upgrade --target "$TARGET" "$HERE"/*.whl
PYTHONPATH="$TARGET${PYTHONPATH:+:$PYTHONPATH}" python3 -c "
import jax, diffrax, equinox, lineax, optimistix
print('jax', jax.__version__, 'diffrax', diffrax.__version__, 'equinox', equinox.__version__,
      'lineax', lineax.__version__, 'optimistix', optimistix.__version__, 'devices', jax.devices())"
EOF
chmod +x "$DEST/install.sh"
# never committed: .git/info/exclude (not .gitignore)
EXCLUDE="$(git rev-parse --git-path info/exclude)"
grep -qxF "/$DEST/" "$EXCLUDE" 2>/dev/null || echo "/$DEST/" >> "$EXCLUDE"
ls -l "$DEST" && du -sh "$DEST"
