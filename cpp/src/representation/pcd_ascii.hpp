#pragma once
// Which ASCII PCD values PCL stores as written.
//
// PCL 1.13 reads an ASCII value by stream extraction into the field's type and, when that
// fails, by atof and a cast. Its stream is shared by all the values of a file and its
// end-of-file state never cleared, so only the file's first value is extracted; every
// other goes through atof and the cast. Both ways read a prefix and neither says so:
// "0x1p3" loads as 0 first and as 8 later, "1e3" in an integer field as 1 first, ".5" as 0
// and "inf" as -2^31 anywhere, 70000 as 4464 in a 2-byte unsigned field (the cast's
// overflow), and an 8-byte integer over 2^53 rounded by the double (2^64 - 1 as 0). So a
// value is accepted only when its whole text is a number of the grammar below that both
// ways store as written.

#include <optional>
#include <string>

namespace spectral_vs::detail {

/// The type of a PCD field, from its TYPE and SIZE lines.
struct PcdValueType {
  char type = 'F';  ///< 'F' (floating point), 'I' (signed) or 'U' (unsigned integer).
  int size = 4;     ///< Bytes: 4 or 8 for 'F'; 1, 2, 4 or 8 for 'I' and 'U'.
};

/// Nothing when PCL stores `token` as written in a field of `type`, else why not (to
/// follow the value in a message, e.g. "is not an integer").
/// - 'F': [+-] then digits with an optional point (at least one digit) and an optional
///   exponent e[+-]digits; or nan, inf, infinity in any case. Refused: hexadecimal, a
///   dangling exponent ("5e"), trailing characters ("1,"), a finite number beyond the
///   type's range (PCL stores it as infinity). Underflow rounds to zero, as stored.
/// - 'I', 'U': [+-] then decimal digits, within the type's range (an unsigned field takes
///   no negative value) and, for 8-byte fields, of magnitude at most 2^53 (what the
///   double of atof holds exactly). Refused: fractions, exponents, nan and inf.
std::optional<std::string> ascii_value_problem(const std::string& token, PcdValueType type);

}  // namespace spectral_vs::detail
