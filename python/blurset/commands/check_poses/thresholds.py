"""The thresholds of the check and its exit codes (calibrated, see the comments)."""

from __future__ import annotations

# Calibrated on fern images_8 (COLMAP-made poses) and on rendered demo builds; see the
# module tests. A 5° perturbation of one view is far outside, correct poses far inside.
ROT_THRESHOLD_DEG = 1.5
CENTER_THRESHOLD_REL = 0.03
MIN_REGISTERED_FRACTION = 0.8
# A view COLMAP places elsewhere still passes when our pose reprojects its features
# about as well as COLMAP's own solution does (median px per view).
REPROJ_RATIO = 1.5
REPROJ_SLACK_PX = 0.25
OUTLIER_PX = 2.0
# A feature of a blurry image lies somewhere on the streak its exposure draws (from the
# first to the last latent frame), not exactly where the mean latent pose projects it:
# SIFT on a blur, and on the ghost copies of a few latent frames, lands off the middle
# along the streak, the more so the longer the streak (measured on the demo box, blur_3
# at 192 px, 6 latent frames: one view's features 1.9 px along its streak on average, 0.4
# px across; a tenth of the features more than 0.35-0.45 of their streak's length off the
# mean pose's projection, i.e. on the first or last ghost). Along the streak, an offset
# up to this fraction of the streak's length (first to last latent frame, projected
# through our poses, per feature) either way is no error; across it, all of it is.
# Measured on the demo box, blur_3, 128 and 192 px, 17-34 views: 0.25 and 0.5 leave the
# same margin under the threshold (0.2-0.4 px) on correct poses, but 0.5 lets a 5° roll
# pass more often (128 px: 10-22 of 15-34 planted rolls caught, against 11-30 at 0.25),
# so a quarter. Errors across the motion keep their full weight, and the planted 5°
# errors say whether the check is still sensitive.
STREAK_FORGIVEN = 0.25
# Fewer registered views than this cannot fix a similarity robustly.
MIN_REGISTERED_VIEWS = 3
# The sensitivity of a pass: a PLANT_DEG rotation planted in one pose (each registered
# view, about each camera axis) must be caught in PLANT_MIN_CAUGHT of the cases, or the
# scene is "not checkable" at its size and view count (bench/check_poses_sensitivity.py).
PLANT_DEG = 5.0
PLANT_AXES = ("tilt", "pan", "roll")
PLANT_MIN_CAUGHT = 0.9
# When most views contradict COLMAP's model, it maps again with these seeds.
RERUN_SEEDS = (1, 2)

IMAGE_SUFFIXES = {".png", ".jpg", ".jpeg"}

EXIT_PASS, EXIT_FAIL, EXIT_NOT_CHECKABLE = 0, 1, 3
