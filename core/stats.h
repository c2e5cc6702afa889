// Small robust statistics shared by the pipeline.
#pragma once

#include <algorithm>
#include <cstddef>
#include <vector>

#include "core/error.h"

namespace crease {

// The median of `values` (taken by value: reordered), the upper one of an even
// count. Throws Error when empty.
inline double Median(std::vector<double> values) {
  Require(!values.empty(), "Median of no values");
  const auto mid = values.begin() + static_cast<std::ptrdiff_t>(values.size() / 2);
  std::nth_element(values.begin(), mid, values.end());
  return *mid;
}

}  // namespace crease
