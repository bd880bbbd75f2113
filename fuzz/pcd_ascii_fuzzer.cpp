// ASCII PCD numbers in every field type. The first byte picks the TYPE and SIZE of the
// fields x, y and z (F 4, F 8, I 1-8, U 1-8); the rest is one value, which the file holds
// twice: as its first value (x of point 0) and as a later one (y of point 1), because
// PCL parses the two differently (pcd_ascii.hpp). A file that loads must hold the value
// as written in both places: for an integer, the decimal digits themselves; for a float,
// the text correctly rounded to the field's type.

#include "fuzz_support.hpp"

#include <cmath>
#include <cstdlib>
#include <string>

namespace {

using spectral_vs::fuzz::check;

struct FieldType {
  char type;
  int size;
};

constexpr FieldType kTypes[] = {{'F', 4}, {'F', 8}, {'I', 1}, {'I', 2}, {'I', 4},
                                {'I', 8}, {'U', 1}, {'U', 2}, {'U', 4}, {'U', 8}};

// The integer `text` spells ([+-]digits), or false when it spells none or one over 2^60.
bool spelled_integer(const std::string& text, double& value) {
  std::size_t i = text.empty() || (text[0] != '+' && text[0] != '-') ? 0 : 1;
  if (i == text.size()) return false;
  long double magnitude = 0;
  for (; i < text.size(); ++i) {
    if (text[i] < '0' || text[i] > '9') return false;
    magnitude = magnitude * 10 + (text[i] - '0');
    if (magnitude > 0x1p60L) return false;
  }
  value = double(text[0] == '-' ? -magnitude : magnitude);
  return true;
}

// The float `text` spells, correctly rounded to the field's type, when all of it is read.
bool spelled_float(const std::string& text, int size, double& value) {
  char* end = nullptr;
  value = size == 4 ? double(std::strtof(text.c_str(), &end)) : std::strtod(text.c_str(), &end);
  return !text.empty() && end == text.c_str() + text.size();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 2) return 0;
  const FieldType field = kTypes[data[0] % 10];
  std::string value;
  for (size_t i = 1; i < size && value.size() < 64; ++i) {
    const char c = static_cast<char>(data[i]);
    if (c != ' ' && c != '\t' && c != '\r' && c != '\n' && c != '\0') value += c;
  }
  if (value.empty()) return 0;
  const std::string type(1, field.type), bytes = std::to_string(field.size);
  const std::string text = "VERSION 0.7\nFIELDS x y z\nSIZE " + bytes + " " + bytes + " " + bytes +
                           "\nTYPE " + type + " " + type + " " + type +
                           "\nCOUNT 1 1 1\nWIDTH 2\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\n"
                           "POINTS 2\nDATA ascii\n" +
                           value + " 1 1\n1 " + value + " 1\n";
  const std::string& path = spectral_vs::fuzz::input_file(
      reinterpret_cast<const uint8_t*>(text.data()), text.size(), ".pcd");
  spectral_vs::CloudFileInfo info;
  spectral_vs::PointCloud cloud;
  try {
    cloud = spectral_vs::load_cloud(path, &info);
  } catch (const std::invalid_argument&) {
    return 0;  // refused: with the line and the field named (the tests check the message)
  }
  // A file that loads has a finite point, so the value is finite in both places.
  double expected = 0.0;
  const bool spelled = field.type == 'F' ? spelled_float(value, field.size, expected)
                                         : spelled_integer(value, expected);
  check(spelled && std::isfinite(expected),
        "a " + type + bytes + " field loaded '" + value + "', which spells no finite number");
  check(cloud.size() == 2 && info.non_finite_dropped == 0, "a finite value dropped a point");
  check(cloud.points()(0, 0) == expected, "the first value of '" + value + "' is misread");
  check(cloud.points()(1, 1) == expected, "a later value of '" + value + "' is misread");
  return 0;
}
