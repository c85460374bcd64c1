#pragma once
// A correction every user of OpenCV's SIFT in omnirig applies to the keypoint positions.

namespace omnirig {

// OpenCV's SIFT doubles its input with INTER_LINEAR (pixel j of the double image is input pixel
// j / 2 - 0.25) but reports positions as if it were j / 2: every keypoint lies 0.25 input pixels
// too far right and down, at every octave (opencv/opencv#23123; the fix, enable_precise_upscale,
// arrived in 4.8 and is off by default; Debian 12 ships 4.6). Subtract this from x and y of
// every keypoint, in the pixels of the image SIFT ran on. engine/slam's features test checks it
// (keypoints of an image and of its half turn agree).
constexpr double kOpenCvSiftUpscaleBiasPx = 0.25;

}  // namespace omnirig
