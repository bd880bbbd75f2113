#pragma once
// Argument checks shared by the implementation. Every message names the argument
// and the limit it broke, because that is what a user needs to fix the call.

#include <cmath>
#include <sstream>
#include <stdexcept>
#include <string>

namespace spectral_vs::detail {

template <typename... Parts>
[[noreturn]] void fail(const Parts&... parts) {
  std::ostringstream message;
  (message << ... << parts);
  throw std::invalid_argument(message.str());
}

inline void require_positive_finite(double value, const char* argument) {
  if (!std::isfinite(value) || value <= 0.0) {
    fail(argument, " must be finite and > 0, got ", value);
  }
}

}  // namespace spectral_vs::detail
