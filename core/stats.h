#pragma once
// Order statistics with one meaning across previz (issue 34): the q-quantile of n values is the
// value of rank floor(q n) (0-based, clamped to n - 1) — an observed value, never an average —
// so the median of an even count is the upper of the two middle values. 0 for no values. O(n)
// (nth_element on the copy).
#include <algorithm>
#include <cstddef>
#include <vector>

namespace previz {

template <typename T>
double quantile(std::vector<T> v, double q) {
  if (v.empty()) return 0;
  const double rank = std::max(0.0, q) * static_cast<double>(v.size());
  const size_t k = std::min(v.size() - 1, static_cast<size_t>(rank));
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return static_cast<double>(v[k]);
}

template <typename T>
double median(std::vector<T> v) {
  return quantile(std::move(v), 0.5);
}

}  // namespace previz
