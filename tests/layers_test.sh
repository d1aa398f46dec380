#!/usr/bin/env bash
# The layering check holds on the tree, and fails, naming the file, when an include crosses a
# layer the wrong way: a daemon including the CLI, the CLI including a daemon, one daemon
# including another, the core including the station, the core opening files.
set -euo pipefail
src=$1
check=$src/cmake/check_layers.cmake
cmake -DROOT="$src" -P "$check"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
expect_failure() {  # FILE LINE PATTERN
  rm -rf "$tmp/tree"
  mkdir -p "$tmp/tree"
  for d in core calib io flags pipeline display station daemons cli; do
    [ -d "$src/$d" ] && cp -r "$src/$d" "$tmp/tree/"
  done
  echo "$2" >>"$tmp/tree/$1"
  if out=$(cmake -DROOT="$tmp/tree" -P "$check" 2>&1); then
    echo "layers_test: '$2' in $1 was not caught"
    exit 1
  fi
  if ! grep -q "$3" <<<"$out"; then
    echo "layers_test: the failure does not name $3:"
    echo "$out"
    exit 1
  fi
  echo "layers_test: caught $1: $2"
}
expect_failure daemons/decoder/main.cc '#include "cli/commands.h"' "daemons/decoder/main.cc: #include \"cli/commands.h\""
expect_failure cli/main.cc '#include "daemons/camera/v4l2_camera.h"' "cli/main.cc: #include \"daemons/camera"
expect_failure daemons/restorer/main.cc '#include "daemons/decoder/x.h"' "a daemon includes no other daemon"
expect_failure core/mesh/mesh.cc '#include "station/node.h"' "core/mesh/mesh.cc"
expect_failure core/mesh/mesh.cc '#include <fstream>' "is pure"
expect_failure io/ply.cc '#include "flags/flags.h"' "io/ply.cc"
echo "layers_test: every wrong-way include was caught"
