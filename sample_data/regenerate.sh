#!/bin/sh
# Regenerate every file in sample_data/ from its scene (deterministic: same seeds, same samples).
# Run from the repository root: sh sample_data/regenerate.sh   (about 10 s)
set -e
LT="${LABTOOL:-.venv/bin/labtool}"
for rpm in 180 300 500; do
  "$LT" acquire --scene "sample_data/scenes/run_${rpm}rpm.toml" --fast --force -o "sample_data/run_${rpm}rpm.h5"
done
"$LT" acquire --scene sample_data/scenes/calibration_79p6Hz.toml --fast --force -o sample_data/calibration_79p6Hz.h5
"$LT" acquire --scene sample_data/scenes/calibration_79p6Hz_aE_n.toml --fast --force -o sample_data/calibration_79p6Hz_aE_n.h5
# one file for both channels, each from the recording with it on the exciter
"$LT" calibrate sample_data/calibration_79p6Hz.h5 sample_data/calibration_79p6Hz_aE_n.h5 \
      --channel aE_t=sample_data/calibration_79p6Hz.h5 --channel aE_n=sample_data/calibration_79p6Hz_aE_n.h5 \
      --reference-accel 9.81 --reference-freq 79.6 --convention peak --force -o sample_data/calibration.toml
