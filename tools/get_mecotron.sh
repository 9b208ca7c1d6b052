#!/bin/sh
# Puts a copy of the course's Arduino sources (software/Arduino of meco-group/mecotron: the
# libraries microOS and components, the CT-Student template) where the firmware-in-the-loop test
# looks for them: ${XDG_CACHE_HOME:-~/.cache}/cartctl/mecotron, or $CARTCTL_MECOTRON if set.
# Never inside this repository: none of the course's code is committed to cartctl.
#
#   tools/get_mecotron.sh          clone https://github.com/meco-group/mecotron (software/Arduino
#                                  only, sparse and without history)
#   tools/get_mecotron.sh SRC      copy it from SRC: a checkout of mecotron, or a git directory
#                                  (bare, a mirror, or a checkout's .git), at its HEAD
#
# Then: python -m pytest -m fil -s tests/test_firmware_fil.py
set -eu

URL=https://github.com/meco-group/mecotron
DEST=${CARTCTL_MECOTRON:-${XDG_CACHE_HOME:-$HOME/.cache}/cartctl/mecotron}
SUB=software/Arduino

case "$DEST" in
  "$(git rev-parse --show-toplevel 2>/dev/null || echo /nonexistent)"*)
    echo "get_mecotron.sh: $DEST is inside this repository; choose a folder outside it" >&2
    exit 2 ;;
esac

work=$(mktemp -d "${TMPDIR:-/tmp}/mecotron.XXXXXX")
trap 'rm -rf "$work"' EXIT INT TERM

if [ $# -eq 0 ]; then
  git clone --quiet --depth 1 --filter=blob:none --sparse "$URL" "$work/repo"
  git -C "$work/repo" sparse-checkout set "$SUB"
  origin="$URL at $(git -C "$work/repo" rev-parse HEAD)"
  mkdir -p "$work/out/software"
  cp -R "$work/repo/$SUB" "$work/out/software/"
else
  src=$1
  if [ -d "$src/$SUB/libraries/microOS" ]; then
    mkdir -p "$work/out/software"
    cp -R "$src/$SUB" "$work/out/software/"
    origin="$src (a checkout)"
  else
    gitdir=$src
    [ -e "$src/.git" ] && gitdir=$src/.git
    if ! commit=$(git --git-dir="$gitdir" rev-parse --verify --quiet HEAD); then
      echo "get_mecotron.sh: $src is neither a mecotron checkout nor a git directory" >&2
      exit 2
    fi
    mkdir -p "$work/out"
    # HEAD:software/Arduino, not HEAD -- software/Arduino: a mirror may lack the large blobs
    # elsewhere in the tree (the desktop installers), which git archive would try to read
    git --git-dir="$gitdir" archive --prefix="$SUB/" "HEAD:$SUB" | tar -x -C "$work/out"
    origin="$src at $commit"
  fi
fi

for need in "$SUB/libraries/microOS/microOS.h" "$SUB/libraries/components/encoder.h" \
            "$SUB/CT-Student/mecotron.h"; do
  if [ ! -f "$work/out/$need" ]; then
    echo "get_mecotron.sh: $need is missing in $origin" >&2
    exit 1
  fi
done

echo "$origin" > "$work/out/SOURCE"
mkdir -p "$(dirname "$DEST")"
rm -rf "$DEST"
mv "$work/out" "$DEST"
echo "course sources from $origin in $DEST"
