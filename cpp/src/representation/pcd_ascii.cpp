#include "representation/pcd_ascii.hpp"

#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <string_view>

namespace spectral_vs::detail {

namespace {

bool is_digit(char c) { return std::isdigit(static_cast<unsigned char>(c)) != 0; }

// `text` without one leading sign.
std::string_view unsigned_part(std::string_view text) {
  if (!text.empty() && (text.front() == '+' || text.front() == '-')) text.remove_prefix(1);
  return text;
}

bool equals_ignoring_case(std::string_view text, std::string_view word) {
  if (text.size() != word.size()) return false;
  for (std::size_t i = 0; i < text.size(); ++i) {
    if (std::tolower(static_cast<unsigned char>(text[i])) != word[i]) return false;
  }
  return true;
}

// Digits, an optional point and more digits (one digit at least), then an optional
// exponent with digits.
bool is_decimal(std::string_view text) {
  std::size_t i = 0, digits = 0;
  for (; i < text.size() && is_digit(text[i]); ++i) ++digits;
  if (i < text.size() && text[i] == '.') {
    for (++i; i < text.size() && is_digit(text[i]); ++i) ++digits;
  }
  if (digits == 0) return false;
  if (i < text.size() && (text[i] == 'e' || text[i] == 'E')) {
    ++i;
    if (i < text.size() && (text[i] == '+' || text[i] == '-')) ++i;
    const std::size_t exponent_start = i;
    for (; i < text.size() && is_digit(text[i]); ++i) {
    }
    if (i == exponent_start) return false;
  }
  return i == text.size();
}

std::optional<std::string> floating_problem(const std::string& token, int size) {
  const std::string_view body = unsigned_part(token);
  if (equals_ignoring_case(body, "nan") || equals_ignoring_case(body, "inf") ||
      equals_ignoring_case(body, "infinity")) {
    return std::nullopt;
  }
  if (!is_decimal(body)) return "is not a decimal number";
  // The grammar holds only '.' as a decimal point, which strtod of the "C" locale reads.
  const double value = std::strtod(token.c_str(), nullptr);
  const float single = std::strtof(token.c_str(), nullptr);
  if (std::isinf(size == 4 ? double(single) : value)) {
    return "is beyond the range of a " + std::to_string(size) + "-byte float";
  }
  // PCL reads all but a file's first value through atof's double: a decimal that lies
  // within a double's rounding of a midpoint of two floats rounds differently twice.
  if (size == 4 && static_cast<float>(value) != single) {
    return "rounds to a different float through a double, as PCL reads it";
  }
  return std::nullopt;
}

std::optional<std::string> integer_problem(const std::string& token, PcdValueType type) {
  const std::string_view digits = unsigned_part(token);
  const bool negative = !token.empty() && token.front() == '-';
  const auto only_digits = [](std::string_view text) {
    for (const char c : text) {
      if (!is_digit(c)) return false;
    }
    return !text.empty();
  };
  if (!only_digits(digits)) return "is not an integer";
  const int bits = 8 * type.size;
  const bool is_signed = type.type == 'I';
  // The largest magnitude of each sign, as unsigned 64-bit numbers.
  const unsigned long long largest_positive =
      is_signed
          ? (1ULL << (bits - 1)) - 1
          : (bits == 64 ? std::numeric_limits<unsigned long long>::max() : (1ULL << bits) - 1);
  const unsigned long long largest_negative = is_signed ? (1ULL << (bits - 1)) : 0;
  errno = 0;
  const unsigned long long magnitude = std::strtoull(std::string(digits).c_str(), nullptr, 10);
  const bool too_large =
      errno == ERANGE || magnitude > (negative ? largest_negative : largest_positive);
  if (!too_large) {
    // atof's double holds integers exactly up to 2^53; PCL casts it to the field's type.
    constexpr unsigned long long kExactInDouble = 1ULL << 53;
    if (magnitude <= kExactInDouble) return std::nullopt;
    return "is beyond 2^53 = 9007199254740992, which PCL reads through a double";
  }
  const std::string lowest = is_signed ? "-" + std::to_string(largest_negative) : "0";
  return "is outside [" + lowest + ", " + std::to_string(largest_positive) + "] of a " +
         std::to_string(type.size) + "-byte " + (is_signed ? "signed" : "unsigned") + " integer";
}

}  // namespace

std::optional<std::string> ascii_value_problem(const std::string& token, PcdValueType type) {
  return type.type == 'F' ? floating_problem(token, type.size) : integer_problem(token, type);
}

}  // namespace spectral_vs::detail
