#!/bin/sh
# Builds the Embree shadow-ray yardstick (bench only). Needs Debian libembree-dev
# (apt-get install libembree-dev). Output: target/embree-shadow.
set -e
cd "$(dirname "$0")/../.."
mkdir -p target
cc -O3 -march=native -o target/embree-shadow bench/embree/shadow.c -lembree3
echo target/embree-shadow
