#pragma once
// How near a composite comes to the synthetic studio's true one: PSNR, and PSNR over the
// actor's bounding box (issue 7's measure; the demo's report and tests/composite use it).
#include <opencv2/core.hpp>

namespace previz::composite {

// PSNR in dB of two images of the same size and type (8-bit: peak 255), over every channel;
// 99 when they are identical. Throws Error when sizes or types differ or an image is empty.
double psnr(const cv::Mat& a, const cv::Mat& b);

struct ActorPsnr {
  cv::Rect bbox;        // bounding box of the actor mask's non-zero pixels (empty: no actor)
  double psnr_db = 99;  // over bbox; 99 when there is no actor
};
// PSNR of 'composite' against 'truth' (8-bit BGR, same size) over the bounding box of
// actor_mask (8-bit, same size; non-zero = actor).
ActorPsnr actorPsnr(const cv::Mat& composite, const cv::Mat& truth, const cv::Mat& actor_mask);

}  // namespace previz::composite
