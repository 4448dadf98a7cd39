#include "composite/measure.h"

#include <cmath>
#include <string>

#include <opencv2/imgproc.hpp>

#include "core/error.h"

namespace previz::composite {

double psnr(const cv::Mat& a, const cv::Mat& b) {
  if (a.empty() || b.empty() || a.size() != b.size() || a.type() != b.type()) {
    ErrorContext context;
    context.field = "image";
    throw Error("psnr: images differ in size or type or are empty (" + std::to_string(a.cols) + "x" +
                    std::to_string(a.rows) + " vs " + std::to_string(b.cols) + "x" + std::to_string(b.rows) + ")",
                context);
  }
  cv::Mat d;
  cv::absdiff(a, b, d);
  d.convertTo(d, CV_64F);
  const cv::Scalar sq = cv::sum(d.mul(d));
  const double mse = (sq[0] + sq[1] + sq[2] + sq[3]) / (double(d.total()) * d.channels());
  return mse <= 0 ? 99.0 : 10 * std::log10(255.0 * 255.0 / mse);
}

ActorPsnr actorPsnr(const cv::Mat& composite, const cv::Mat& truth, const cv::Mat& actor_mask) {
  if (actor_mask.empty() || actor_mask.size() != composite.size() || actor_mask.type() != CV_8U) {
    ErrorContext context;
    context.field = "actor_mask";
    throw Error("actorPsnr: the actor mask must be 8-bit and of the composite's size", context);
  }
  ActorPsnr out;
  out.bbox = cv::boundingRect(actor_mask);
  if (out.bbox.area() > 0) out.psnr_db = psnr(composite(out.bbox), truth(out.bbox));
  return out;
}

}  // namespace previz::composite
