#include <spectral_vs/representation/cloud_io.hpp>

#include "common/checks.hpp"
#include "common/paths.hpp"
#include "representation/pcd_ascii.hpp"

#include <pcl/PCLPointCloud2.h>
#include <pcl/io/pcd_io.h>
#include <pcl/io/ply_io.h>
#include <pcl/point_types.h>

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <optional>
#include <sstream>
#include <utility>
#include <vector>

namespace spectral_vs {

using detail::fail;

namespace {

enum class Format { pcd, ply };

std::string lower_extension(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return ext;
}

Format format_from_extension(const std::string& path) {
  const std::string ext = lower_extension(path);
  if (ext == ".pcd") return Format::pcd;
  if (ext == ".ply") return Format::ply;
  fail("path: unsupported extension '", ext, "' of ", path, " (supported: .pcd, .ply)");
}

// The tokens of a line as PCL's readers split it: on spaces, tabs and carriage returns
// only. Other control bytes (a vertical tab, a form feed) are part of a token, so a line
// of them is no empty line to PCL: it ends PCL's header there, and its binary reader then
// crashed on the header it had (found by fuzz/pcd_fuzzer).
std::vector<std::string> split(const std::string& line) {
  std::vector<std::string> tokens;
  std::string token;
  for (const char c : line) {
    if (c == ' ' || c == '\t' || c == '\r') {
      if (!token.empty()) tokens.push_back(std::move(token));
      token.clear();
    } else {
      token += c;
    }
  }
  if (!token.empty()) tokens.push_back(std::move(token));
  return tokens;
}

// Text from a file for a message: printable ASCII (other bytes as '?'), at most `length`
// characters, so that a corrupted file cannot put invalid UTF-8 into an exception (which
// Python could not even decode).
std::string printable(const std::string& text, std::size_t length) {
  std::string out;
  for (std::size_t i = 0; i < text.size() && i < length; ++i) {
    const unsigned char c = static_cast<unsigned char>(text[i]);
    out += (c >= 32 && c < 127) ? static_cast<char>(c) : '?';
  }
  return text.size() > length ? out + "..." : out;
}

std::string in_quotes(const std::string& text) { return "'" + printable(text, 40) + "'"; }

// A non-negative integer of a header line, or -1 for anything else.
long long parse_count(const std::string& token) {
  if (token.empty() || token.size() > 12 ||
      !std::all_of(token.begin(), token.end(), [](unsigned char c) { return std::isdigit(c); })) {
    return -1;
  }
  return std::stoll(token);
}

// The bytes of `file` after its read position, which it keeps.
long long bytes_left(std::ifstream& file) {
  const std::streampos at = file.tellg();
  file.seekg(0, std::ios::end);
  const long long left = static_cast<long long>(file.tellg() - at);
  file.seekg(at);
  return left;
}

// PCL's header reader does not stop at the DATA line: it reads on, skipping empty and
// comment lines, and takes the next line that begins with a header keyword (a prefix
// compare: "FIELDSx" counts) as part of the header, while the data still starts after
// DATA. Binary data whose first bytes spell "COLUMNS" so redefined the fields after the
// sizes had been read, and PCL's reader crashed (found by fuzz/pcd_fuzzer). Such a file
// is refused: PCL cannot read it as written.
template <class Bad>
void check_after_data_line(std::ifstream& file, const Bad& bad) {
  static const char* const kKeywords[] = {"VERSION",   "FIELDS", "COLUMNS", "SIZE",
                                          "TYPE",      "COUNT",  "WIDTH",   "HEIGHT",
                                          "VIEWPOINT", "POINTS", "DATA"};
  const std::streampos data_start = file.tellg();
  std::string line;
  for (int lines = 0; lines < 256 && std::getline(file, line); ++lines) {
    const std::vector<std::string> tokens = split(line);
    if (tokens.empty() || tokens[0][0] == '#') continue;
    for (const char* keyword : kKeywords) {
      if (tokens[0].rfind(keyword, 0) == 0) {
        bad("the data after the DATA line begins with ", in_quotes(tokens[0]),
            ", which PCL's reader takes for a header line");
      }
    }
    break;
  }
  file.clear();
  file.seekg(data_start);
}

// A value of an ASCII point: its field's name and type.
struct AsciiValue {
  const std::string* field;
  detail::PcdValueType type;
};
// Values per ASCII point (a line of over a million values is no point cloud).
constexpr long long kMaxAsciiValues = 1 << 20;

// PCL's PCD reader trusts the header: a header that does not match the data can make it
// read past its buffers (a crash) or return zeros for unparsable ASCII values. So the
// whole structure is checked here first: field sizes and types, WIDTH x HEIGHT = POINTS,
// the data's length against the file's (binary), the compressed block's sizes
// (binary_compressed), and every value of every line (ascii).
void check_pcd(const std::string& path) {
  std::ifstream file(path, std::ios::binary);
  if (!file) fail("path: cannot open ", path);
  const auto bad = [&path](const auto&... why) {
    fail("path: ", path, " is not a valid PCD file: ", why...);
  };
  std::vector<std::string> fields, sizes, types, counts;
  long long width = -1, height = 1, points = -1;
  std::string data;
  bool versioned = false;
  std::string line;
  long long line_number = 0;  // of the last line read, from 1
  for (; data.empty(); ++line_number) {
    if (line_number == 256 || !std::getline(file, line)) {
      if (!versioned && fields.empty()) {
        fail("path: ", path, " is not a PCD file (no VERSION or FIELDS header line)");
      }
      bad("the header ends without a DATA line");
    }
    if (line.empty()) continue;
    const std::vector<std::string> tokens = split(line);
    // PCL's reader skips an empty line but ends its header at one of spaces, tabs or a
    // carriage return (a blank line of a CRLF file), and its reader then crashed on the
    // header it had (found by fuzz/pcd_fuzzer).
    if (tokens.empty()) bad("a header line of white space only ends PCL's header there");
    if (tokens[0][0] == '#') continue;
    const std::string& key = tokens[0];
    const std::vector<std::string> values(tokens.begin() + 1, tokens.end());
    if (key == "VERSION") {
      versioned = true;
    } else if (key == "VIEWPOINT") {
      const auto is_float = [](const std::string& value) {
        return !detail::ascii_value_problem(value, {'F', 4});
      };
      if (values.size() != 7 || !std::all_of(values.begin(), values.end(), is_float)) {
        bad("VIEWPOINT must be 7 decimal numbers, got ", in_quotes(line));
      }
    } else if (key == "FIELDS" || key == "COLUMNS") {
      fields = values;
    } else if (key == "SIZE") {
      sizes = values;
    } else if (key == "TYPE") {
      types = values;
    } else if (key == "COUNT") {
      counts = values;
    } else if (key == "WIDTH" || key == "HEIGHT" || key == "POINTS") {
      const long long value = values.size() == 1 ? parse_count(values[0]) : -1;
      if (value < 0 || value > std::numeric_limits<std::uint32_t>::max()) {
        bad(key, " must be a count, got ", in_quotes(line));
      }
      (key == "WIDTH" ? width : key == "HEIGHT" ? height : points) = value;
    } else if (key == "DATA") {
      if (values.size() != 1) bad(in_quotes(line));
      data = values[0];
    } else if (!versioned && fields.empty()) {
      fail("path: ", path, " is not a PCD file (no VERSION or FIELDS header line)");
    } else {
      // PCL's reader ends the header at a line it does not know and reads on from there.
      bad("unknown header line ", in_quotes(line));
    }
  }
  check_after_data_line(file, bad);
  if (fields.empty()) bad("no FIELDS");
  if (counts.empty()) counts.assign(fields.size(), "1");
  if (sizes.size() != fields.size() || types.size() != fields.size() ||
      counts.size() != fields.size()) {
    bad(fields.size(), " FIELDS but ", sizes.size(), " SIZE, ", types.size(), " TYPE and ",
        counts.size(), " COUNT entries");
  }
  long long point_step = 0, values_per_point = 0;
  std::vector<AsciiValue> ascii_values;  // of a point, field by field
  for (std::size_t i = 0; i < fields.size(); ++i) {
    const long long size = parse_count(sizes[i]);
    const long long count = parse_count(counts[i]);
    const std::string& type = types[i];
    const bool valid_type =
        (type == "F" && (size == 4 || size == 8)) ||
        ((type == "I" || type == "U") && (size == 1 || size == 2 || size == 4 || size == 8));
    if (!valid_type)
      bad("field ", in_quotes(fields[i]), " has TYPE ", in_quotes(type), " and SIZE ",
          in_quotes(sizes[i]));
    if (count < 1 || count > 65536)
      bad("field ", in_quotes(fields[i]), " has COUNT ", in_quotes(counts[i]));
    point_step += size * count;
    values_per_point += count;
    if (data == "ascii" && values_per_point <= kMaxAsciiValues) {
      ascii_values.insert(ascii_values.end(), std::size_t(count),
                          AsciiValue{&fields[i], {type[0], int(size)}});
    }
  }
  if (width < 0 || points < 0) bad("no WIDTH or no POINTS");
  if (width * height != points)
    bad("WIDTH x HEIGHT = ", width, " x ", height, " but POINTS = ", points);

  // The data after the header line.
  const std::streamoff header_end = file.tellg();
  const long long available = bytes_left(file);
  if (data == "binary") {
    if (available < points * point_step) {
      fail("path: ", path, " is truncated: ", available, " bytes of data for ", points,
           " points of ", point_step, " bytes");
    }
  } else if (data == "binary_compressed") {
    if (points == 0) return;
    std::uint32_t block[2] = {0, 0};
    file.seekg(header_end);
    if (available < 8 || !file.read(reinterpret_cast<char*>(block), sizeof(block))) {
      fail("path: ", path, " is truncated: no compressed data block");
    }
    if (static_cast<long long>(block[1]) != points * point_step) {
      bad("the compressed block holds ", block[1], " bytes, ", points, " points of ", point_step,
          " bytes need ", points * point_step);
    }
    if (static_cast<long long>(block[0]) > available - 8 || block[0] == 0) {
      fail("path: ", path, " is truncated: ", available - 8,
           " bytes of compressed data, the header of the "
           "block says ",
           block[0]);
    }
  } else if (data == "ascii") {
    file.clear();
    file.seekg(header_end);
    if (values_per_point > kMaxAsciiValues) {
      bad(values_per_point, " values per point, over the ", kMaxAsciiValues,
          " an ASCII line may hold");
    }
    long long read = 0;
    while (read < points && std::getline(file, line)) {
      ++line_number;
      // PCL skips only a line with no byte: one of white space is a point of no values.
      if (line.empty()) continue;
      const std::vector<std::string> tokens = split(line);
      if (static_cast<long long>(tokens.size()) != values_per_point) {
        bad("line ", line_number, ": point ", read, " has ", tokens.size(),
            " values, the header gives ", values_per_point);
      }
      for (std::size_t v = 0; v < tokens.size(); ++v) {
        const AsciiValue& value = ascii_values[v];
        if (*value.field == "_") continue;  // padding, which PCL skips
        if (const auto problem = detail::ascii_value_problem(tokens[v], value.type)) {
          bad("line ", line_number, ": point ", read, ", field ", in_quotes(*value.field),
              " (TYPE ", value.type.type, " SIZE ", value.type.size, "): ", in_quotes(tokens[v]),
              " ", *problem);
        }
      }
      ++read;
    }
    if (read < points) fail("path: ", path, " is truncated: ", read, " of ", points, " points");
  } else {
    bad("DATA must be ascii, binary or binary_compressed, got ", in_quotes(data));
  }
}

// Bytes of a PLY scalar type, or 0 for a name that is not one.
int ply_type_size(const std::string& type) {
  static const std::pair<const char*, int> kTypes[] = {
      {"char", 1},  {"uchar", 1},   {"int8", 1},   {"uint8", 1},  {"short", 2}, {"ushort", 2},
      {"int16", 2}, {"uint16", 2},  {"int", 4},    {"uint", 4},   {"int32", 4}, {"uint32", 4},
      {"float", 4}, {"float32", 4}, {"double", 8}, {"float64", 8}};
  for (const auto& [name, size] : kTypes) {
    if (type == name) return size;
  }
  return 0;
}

struct PlyProperty {
  std::string name, type;  // a list's type is its items'
  bool list = false;
  int bytes = 0;           // a scalar's size, or a list's count size
  std::string count_type;  // a list's
};

// What a PLY header says of the points: the vertex count and, for an organized cloud, the
// count of its range_grid element (the lattice, -1 without one).
struct PlyLayout {
  long long vertices = 0;
  long long grid = -1;
};

struct PlyElement {
  std::string name;
  long long count = 0;
  std::vector<PlyProperty> properties;
};

// PCL's PLY reader handles a uchar red, green, blue (and alpha) of the vertices as one
// packed colour field, and asserts (aborts the process) or writes a property over another
// when they come in another order. So they must be one run: red, green, blue, then alpha.
template <class Bad>
void check_ply_colours(const PlyElement& vertex, const Bad& bad) {
  std::vector<std::string> colours;
  std::vector<std::size_t> at;
  for (std::size_t i = 0; i < vertex.properties.size(); ++i) {
    const PlyProperty& property = vertex.properties[i];
    if (property.type != "uchar" && property.type != "uint8") continue;
    std::string name = property.name;
    if (name.rfind("diffuse_", 0) == 0) name = name.substr(8);
    if (name == "red" || name == "green" || name == "blue" || name == "alpha") {
      colours.push_back(name);
      at.push_back(i);
    }
  }
  const std::vector<std::vector<std::string>> allowed = {
      {}, {"red", "green", "blue"}, {"red", "green", "blue", "alpha"}};
  const bool adjacent = colours.empty() || at.back() - at.front() + 1 == at.size();
  if (!adjacent || std::find(allowed.begin(), allowed.end(), colours) == allowed.end()) {
    bad("the vertex colours must be uchar red, green, blue and an optional alpha, one after "
        "the other");
  }
}

// A `property` header line: `property TYPE NAME` or `property list COUNT_TYPE TYPE NAME`.
template <class Bad>
PlyProperty parse_ply_property(const std::vector<std::string>& tokens, const std::string& line,
                               const Bad& bad) {
  PlyProperty property;
  property.list = tokens.size() == 5 && tokens[1] == "list";
  if (property.list) {
    property.bytes = ply_type_size(tokens[2]);
    property.count_type = tokens[2];
    property.type = tokens[3];
    property.name = tokens[4];
    if (property.bytes == 0 || ply_type_size(tokens[3]) == 0) {
      bad("unknown list type in ", in_quotes(line));
    }
  } else if (tokens.size() == 3) {
    property.type = tokens[1];
    property.name = tokens[2];
    property.bytes = ply_type_size(tokens[1]);
    if (property.bytes == 0) bad("unknown property type in ", in_quotes(line));
  } else {
    bad("a property must be 'property TYPE NAME' or 'property list COUNT_TYPE TYPE NAME', got ",
        in_quotes(line));
  }
  return property;
}

// A binary PLY scalar of `type` at `at`, in the file's byte order, as a double.
double ply_scalar(const char* at, const std::string& type, bool big_endian) {
  const int size = ply_type_size(type);
  unsigned char bytes[8];
  std::memcpy(bytes, at, std::size_t(size));
  if (big_endian) std::reverse(bytes, bytes + size);
  const auto as = [&bytes](auto typed) {
    std::memcpy(&typed, bytes, sizeof(typed));
    return static_cast<double>(typed);
  };
  if (type == "char" || type == "int8") return as(std::int8_t{});
  if (type == "uchar" || type == "uint8") return as(std::uint8_t{});
  if (type == "short" || type == "int16") return as(std::int16_t{});
  if (type == "ushort" || type == "uint16") return as(std::uint16_t{});
  if (type == "int" || type == "int32") return as(std::int32_t{});
  if (type == "uint" || type == "uint32") return as(std::uint32_t{});
  if (type == "float" || type == "float32") return as(float{});
  return as(double{});
}

// The values of one element instance, property by property (a list as its items), read
// from an ASCII line or from binary data; false when the data ends first.
class PlyInstanceReader {
 public:
  PlyInstanceReader(std::ifstream& file, bool ascii, bool big_endian)
      : file_(file), ascii_(ascii), big_endian_(big_endian) {}

  // Calls `item(value text, or "" for binary data, value)` for each list item of the instance.
  template <class Item>
  bool read(const std::vector<PlyProperty>& properties, const Item& item) {
    if (ascii_) return read_ascii(properties, item);
    for (const PlyProperty& property : properties) {
      char buffer[8];
      if (!file_.read(buffer, property.bytes)) return false;
      if (!property.list) continue;
      const double count = ply_scalar(buffer, property.count_type, big_endian_);
      if (!(count >= 0 && count < 2147483648.0)) return false;
      const int size = ply_type_size(property.type);
      for (long long k = 0; k < static_cast<long long>(count); ++k) {
        if (!file_.read(buffer, size)) return false;
        item(std::string(), ply_scalar(buffer, property.type, big_endian_));
      }
    }
    return true;
  }

 private:
  template <class Item>
  bool read_ascii(const std::vector<PlyProperty>& properties, const Item& item) {
    std::string line;
    if (!std::getline(file_, line)) return false;
    const std::vector<std::string> tokens = split(line);
    std::size_t at = 0;
    for (const PlyProperty& property : properties) {
      if (at >= tokens.size()) return false;
      if (!property.list) {
        ++at;
        continue;
      }
      const long long count = parse_count(tokens[at++]);
      if (count < 0 || count > static_cast<long long>(tokens.size() - at)) return false;
      for (long long k = 0; k < count; ++k, ++at) item(tokens[at], 0.0);
    }
    return true;
  }

  std::ifstream& file_;
  bool ascii_, big_endian_;
};

// PCL's PLY reader fills an organized cloud's cell from the vertex that the cell's
// range_grid list names first, without checking it: an index of -1 or past the vertices
// read outside its buffer (a crash, found by fuzz/ply_fuzzer). Every index is checked
// here, walking the elements before range_grid as PCL does (an ASCII instance per line).
template <class Bad>
void check_ply_range_grid(std::ifstream& file, const std::vector<PlyElement>& elements,
                          const std::string& format, long long vertices, const Bad& bad) {
  const std::streampos data_start = file.tellg();
  PlyInstanceReader reader(file, format == "ascii", format == "binary_big_endian");
  for (const PlyElement& element : elements) {
    const bool grid = element.name == "range_grid";
    for (long long i = 0; i < element.count; ++i) {
      const auto check_index = [&](const std::string& text, double value) {
        if (!grid) return;
        if (!text.empty()) {
          char* end = nullptr;
          value = std::strtod(text.c_str(), &end);
          if (*end != '\0') value = -1.0;
        }
        if (!(value >= 0 && value < double(vertices) && value == std::floor(value))) {
          std::ostringstream name;
          name << value;
          bad("range_grid cell ", i, " names vertex ", in_quotes(text.empty() ? name.str() : text),
              ", not one of the ", vertices, " vertices");
        }
      };
      if (!reader.read(element.properties, check_index)) {
        file.clear();
        file.seekg(data_start);
        return;  // data that ends early or does not parse: PCL's reader refuses it
      }
    }
    if (grid) break;
  }
  file.clear();
  file.seekg(data_start);
}

// PCL's PLY reader asserts (aborts the process) on several headers that do not match
// their data: a list property of the vertices whose length changes (found by
// fuzz/ply_fuzzer), colours out of order, an organized size (obj_info num_cols and
// num_rows) smaller than the vertex count. It also allocates what the header's counts
// ask for before reading. So the header is parsed here first, against the PLY grammar,
// and those cases are refused.
PlyLayout check_ply(const std::string& path) {
  std::ifstream file(path, std::ios::binary);
  if (!file) fail("path: cannot open ", path);
  const auto bad = [&path](const auto&... why) {
    fail("path: ", path, " is not a valid PLY file: ", why...);
  };
  std::string line;
  std::getline(file, line);
  if (split(line) != std::vector<std::string>{"ply"}) {
    fail("path: ", path, " is not a PLY file (first line is not 'ply')");
  }
  std::string format;
  std::vector<PlyElement> elements;
  long long cols = 0, rows = 0;
  for (int lines = 1;; ++lines) {
    if (lines == 4096 || !std::getline(file, line)) bad("the header ends without end_header");
    if (std::any_of(line.begin(), line.end(), [](unsigned char c) {
          return (c < 32 && c != '\t' && c != '\r') || c == 127;
        })) {
      bad("header line ", lines + 1, " holds a control byte");
    }
    const std::vector<std::string> tokens = split(line);
    if (tokens.empty()) bad("header line ", lines + 1, " is empty");
    // PCL's reader finds its keyword past the white space, then splits the line again
    // and asserts (aborts the process) that the first piece is the keyword (found by
    // fuzz/ply_fuzzer on an indented obj_info line).
    if (line[0] == ' ' || line[0] == '\t' || line[0] == '\r')
      bad("header line ", lines + 1, " begins with white space");
    const std::string& key = tokens[0];
    if (key == "end_header") break;
    if (key == "comment") continue;
    if (key == "format") {
      if (tokens.size() != 3 || tokens[2] != "1.0" ||
          (tokens[1] != "ascii" && tokens[1] != "binary_little_endian" &&
           tokens[1] != "binary_big_endian")) {
        bad("the format must be ascii, binary_little_endian or binary_big_endian 1.0, got ",
            in_quotes(line));
      }
      format = tokens[1];
    } else if (key == "obj_info") {
      if (tokens.size() >= 3 && (tokens[1] == "num_cols" || tokens[1] == "num_rows")) {
        const long long value = parse_count(tokens[2]);
        if (value < 0 || value > std::numeric_limits<std::int32_t>::max()) {
          bad(tokens[1], " must be a count, got ", in_quotes(line));
        }
        (tokens[1] == "num_cols" ? cols : rows) = value;
      }
    } else if (key == "element") {
      const long long count = tokens.size() == 3 ? parse_count(tokens[2]) : -1;
      if (count < 0 || count > std::numeric_limits<std::int32_t>::max()) {
        bad("an element must be 'element NAME COUNT', got ", in_quotes(line));
      }
      for (const auto& element : elements) {
        if (element.name == tokens[1]) bad("element ", in_quotes(tokens[1]), " appears twice");
      }
      elements.push_back({tokens[1], count, {}});
      // As PCL's reader: the vertex count is the size unless both were given before.
      if (tokens[1] == "vertex" && (cols == 0 || rows == 0)) {
        cols = count;
        rows = 1;
      }
    } else if (key == "property") {
      if (elements.empty()) bad("a property before any element: ", in_quotes(line));
      const PlyProperty property = parse_ply_property(tokens, line, bad);
      auto& properties = elements.back().properties;
      for (const auto& other : properties) {
        if (other.name == property.name) {
          bad("property ", in_quotes(property.name), " appears twice in element ",
              in_quotes(elements.back().name));
        }
      }
      properties.push_back(property);
    } else {
      bad("unknown header line ", in_quotes(line));
    }
  }
  if (format.empty()) bad("no format line");
  const auto vertex = std::find_if(elements.begin(), elements.end(),
                                   [](const PlyElement& e) { return e.name == "vertex"; });
  if (vertex == elements.end()) bad("no vertex element");
  for (const auto& property : vertex->properties) {
    if (property.list) {
      bad("the vertex property ", in_quotes(property.name),
          " is a list; point clouds with list properties are not supported");
    }
  }
  check_ply_colours(*vertex, bad);
  if (cols * rows < vertex->count) {
    bad("obj_info gives ", cols, " x ", rows, " points, fewer than the ", vertex->count,
        " vertices");
  }
  // Every element's instances need at least this many bytes (a list at least its count;
  // an ASCII value at least one character), so that no count asks for more memory than
  // the file could fill.
  const long long available = bytes_left(file);
  long long needed = 0;
  for (const auto& element : elements) {
    long long per_instance = 0;
    for (const auto& property : element.properties) {
      per_instance += format == "ascii" ? 1 : property.bytes;
    }
    needed += element.count * per_instance;
  }
  if (needed > available) {
    fail("path: ", path, " is truncated: ", available, " bytes of data, the header needs at least ",
         needed);
  }
  const auto grid = std::find_if(elements.begin(), elements.end(),
                                 [](const PlyElement& e) { return e.name == "range_grid"; });
  if (grid != elements.end()) check_ply_range_grid(file, elements, format, vertex->count, bad);
  return {vertex->count, grid == elements.end() ? -1 : grid->count};
}

// PCL's readers print to stderr and may misbehave on a file that is not a point
// cloud, so the file is checked here first. Returns a PLY file's layout (nothing for PCD,
// whose check covers its data).
std::optional<PlyLayout> check_header(const std::string& path, Format format) {
  if (format == Format::pcd) {
    check_pcd(path);
    return std::nullopt;
  }
  return check_ply(path);
}

const pcl::PCLPointField* find_field(const pcl::PCLPointCloud2& cloud, const char* name) {
  for (const auto& field : cloud.fields) {
    if (field.name == name) return &field;
  }
  return nullptr;
}

double read_value(const std::uint8_t* at, std::uint8_t datatype) {
  auto read = [at](auto typed) {
    std::memcpy(&typed, at, sizeof(typed));
    return static_cast<double>(typed);
  };
  switch (datatype) {
    case pcl::PCLPointField::FLOAT32:
      return read(float{});
    case pcl::PCLPointField::FLOAT64:
      return read(double{});
    case pcl::PCLPointField::INT8:
      return read(std::int8_t{});
    case pcl::PCLPointField::UINT8:
      return read(std::uint8_t{});
    case pcl::PCLPointField::INT16:
      return read(std::int16_t{});
    case pcl::PCLPointField::UINT16:
      return read(std::uint16_t{});
    case pcl::PCLPointField::INT32:
      return read(std::int32_t{});
    case pcl::PCLPointField::UINT32:
      return read(std::uint32_t{});
    case pcl::PCLPointField::INT64:
      return read(std::int64_t{});
    case pcl::PCLPointField::UINT64:
      return read(std::uint64_t{});
    default:
      fail("point field of unsupported data type ", int(datatype));
  }
}

std::size_t field_size(std::uint8_t datatype) {
  switch (datatype) {
    case pcl::PCLPointField::FLOAT64:
    case pcl::PCLPointField::INT64:
    case pcl::PCLPointField::UINT64:
      return 8;
    case pcl::PCLPointField::INT16:
    case pcl::PCLPointField::UINT16:
      return 2;
    case pcl::PCLPointField::INT8:
    case pcl::PCLPointField::UINT8:
      return 1;
    default:
      return 4;
  }
}

Points extract(const pcl::PCLPointCloud2& cloud, const pcl::PCLPointField* fields[3],
               const std::string& path) {
  const std::size_t rows = cloud.height;
  const std::size_t cols = cloud.width;
  for (int axis = 0; axis < 3; ++axis) {
    if (fields[axis]->offset + field_size(fields[axis]->datatype) > cloud.point_step) {
      fail("path: ", path, " has a field beyond the point size");
    }
  }
  if (cloud.row_step < cols * cloud.point_step || cloud.data.size() < rows * cloud.row_step) {
    fail("path: ", path, " is truncated: ", cloud.data.size(), " bytes of data for ", rows * cols,
         " points");
  }
  Points out(static_cast<Eigen::Index>(rows * cols), 3);
  // A PLY of no vertices can still be 2^31 - 1 rows high (a camera element's viewport):
  // rows of no point are not walked one by one.
  if (out.rows() == 0) return out;
  for (std::size_t r = 0; r < rows; ++r) {
    for (std::size_t c = 0; c < cols; ++c) {
      const std::uint8_t* point = cloud.data.data() + r * cloud.row_step + c * cloud.point_step;
      const auto index = static_cast<Eigen::Index>(r * cols + c);
      for (int axis = 0; axis < 3; ++axis) {
        out(index, axis) = read_value(point + fields[axis]->offset, fields[axis]->datatype);
      }
    }
  }
  return out;
}

// PCL sizes a PLY cloud by obj_info num_cols x num_rows, a camera element's viewport or
// a range_grid element, whichever it read last. A size over the vertex count without a
// range_grid pads the cloud with zero points (PCL's writer gives such files for a cloud
// with NaN points), so the cloud is cut back to its vertices; a size under it would drop
// vertices without a word, so it is refused.
void match_ply_layout(const PlyLayout& ply, const std::string& path, pcl::PCLPointCloud2& cloud) {
  const std::uint64_t size = std::uint64_t{cloud.width} * cloud.height;
  const auto expected = static_cast<std::uint64_t>(ply.grid >= 0 ? ply.grid : ply.vertices);
  if (size < expected || (ply.grid >= 0 && size != expected)) {
    fail("path: ", path, " is not a valid PLY file: it gives ", cloud.width, " x ", cloud.height,
         " points for ", expected, (ply.grid >= 0 ? " range_grid cells" : " vertices"));
  }
  if (size > expected) {
    cloud.width = static_cast<std::uint32_t>(expected);
    cloud.height = 1;
    cloud.row_step = cloud.point_step * cloud.width;
  }
}

}  // namespace

namespace {

// A file's points (and normals, if it has them) in its order, non-finite values kept.
struct FileContents {
  Points points, normals;
  CloudFileInfo info;
};

// A private copy of a file, removed with the object. PCL memory-maps a binary PCD: when
// another process rewrites the file under the mapping (a camera pipeline writing frames
// while a viewer reads them), reading past its new end raised SIGBUS. A copy made with
// read() cannot fault, and the header check and PCL then see the same bytes.
class Snapshot {
 public:
  explicit Snapshot(const std::string& path) {
    static std::atomic<unsigned long> count{0};
    const std::filesystem::path extension = std::filesystem::path(path).extension();
    path_ = (std::filesystem::temp_directory_path() /
             ("spectral_vs_" + std::to_string(::getpid()) + "_" + std::to_string(count++) +
              extension.string()))
                .string();
    if (const auto kind = detail::path_kind(path); kind != detail::PathKind::file) {
      fail("path: ", detail::path_problem(kind), ": ", path);
    }
    std::ifstream in(path, std::ios::binary);
    if (!in) fail("path: cannot read ", path);
    std::ofstream out(path_, std::ios::binary | std::ios::trunc);
    std::vector<char> block(std::size_t(1) << 16);
    while (in.read(block.data(), std::streamsize(block.size())) || in.gcount() > 0) {
      out.write(block.data(), in.gcount());
    }
    out.close();
    if (!out) {
      std::error_code error;
      std::filesystem::remove(path_, error);
      fail("path: cannot copy ", path, " for reading (to ", path_, ")");
    }
  }
  ~Snapshot() {
    std::error_code ignored;
    std::filesystem::remove(path_, ignored);
  }
  Snapshot(const Snapshot&) = delete;
  Snapshot& operator=(const Snapshot&) = delete;
  const std::string& path() const { return path_; }

 private:
  std::string path_;
};

FileContents read_snapshot(const std::string& path);

FileContents read_file(const std::string& path) {
  format_from_extension(path);  // an unknown extension is named before the file is read
  const Snapshot snapshot(path);
  try {
    return read_snapshot(snapshot.path());
  } catch (const std::invalid_argument& error) {
    // The messages name the file the caller gave.
    std::string message = error.what();
    for (std::size_t at; (at = message.find(snapshot.path())) != std::string::npos;) {
      message.replace(at, snapshot.path().size(), path);
    }
    throw std::invalid_argument(message);
  }
}

FileContents read_snapshot(const std::string& path) {
  const Format format = format_from_extension(path);
  const std::optional<PlyLayout> ply = check_header(path, format);
  pcl::PCLPointCloud2 cloud;
  int status = -1;
  try {
    if (format == Format::pcd) {
      pcl::PCDReader reader;
      status = reader.read(path, cloud);
    } else {
      pcl::PLYReader reader;
      status = reader.read(path, cloud);
    }
  } catch (const std::exception& error) {
    fail("path: cannot read ", path, ": ", printable(error.what(), 200));
  }
  if (status < 0) {
    fail("path: ", path, " could not be parsed as a point cloud");
  }
  if (ply) match_ply_layout(*ply, path, cloud);
  const pcl::PCLPointField* xyz[3] = {find_field(cloud, "x"), find_field(cloud, "y"),
                                      find_field(cloud, "z")};
  if (!xyz[0] || !xyz[1] || !xyz[2]) {
    fail("path: ", path, " has no x, y, z fields");
  }
  FileContents contents;
  contents.points = extract(cloud, xyz, path);
  const pcl::PCLPointField* normal[3] = {
      find_field(cloud, "normal_x"), find_field(cloud, "normal_y"), find_field(cloud, "normal_z")};
  contents.info.had_normals = normal[0] && normal[1] && normal[2];
  if (contents.info.had_normals) contents.normals = extract(cloud, normal, path);
  contents.info.width = cloud.width;
  contents.info.height = cloud.height;
  contents.info.points_in_file = static_cast<std::size_t>(contents.points.rows());
  return contents;
}

}  // namespace

PointCloud load_cloud(const std::string& path, CloudFileInfo* info) {
  FileContents file = read_file(path);
  file.info.non_finite_dropped =
      remove_non_finite(file.points, file.info.had_normals ? &file.normals : nullptr);
  if (file.points.rows() == 0) {
    fail("path: ", path, " holds no finite point (", file.info.points_in_file, " in the file)");
  }
  if (info) *info = file.info;
  return PointCloud(std::move(file.points), std::move(file.normals));
}

Points load_points(const std::string& path, CloudFileInfo* info) {
  FileContents file = read_file(path);
  const bool any_finite = file.points.array().isFinite().rowwise().all().any();
  file.info.non_finite_dropped = 0;
  if (!any_finite) {
    fail("path: ", path, " holds no finite point (", file.info.points_in_file, " in the file)");
  }
  if (info) *info = file.info;
  return std::move(file.points);
}

void save_cloud(const std::string& path, const PointCloud& cloud, PcdEncoding encoding) {
  const Format format = format_from_extension(path);
  require_non_empty(cloud, "cloud");
  // Writing to a FIFO blocks until a reader opens it (a hang), to a folder fails deep
  // inside PCL: only a regular file, or none yet, is written.
  if (const auto kind = detail::path_kind(path);
      kind != detail::PathKind::file && kind != detail::PathKind::missing) {
    fail("path: ", path,
         kind == detail::PathKind::folder ? " is a folder" : " is not a regular file",
         ", not a file to write a cloud to");
  }
  // The files store float32: a coordinate beyond its range would be written as inf.
  constexpr double kFloatMax = double(std::numeric_limits<float>::max());
  for (Eigen::Index i = 0; i < cloud.points().rows(); ++i) {
    if (!(cloud.points().row(i).cwiseAbs().maxCoeff() <= kFloatMax)) {
      fail("cloud: point ", i, " has a coordinate beyond the float32 range of the file (",
           kFloatMax, " m)");
    }
  }
  pcl::PCLPointCloud2 message;
  if (cloud.has_normals()) {
    pcl::PointCloud<pcl::PointNormal> pcl_cloud;
    pcl_cloud.resize(cloud.size());
    for (std::size_t i = 0; i < cloud.size(); ++i) {
      auto& p = pcl_cloud[i];
      p.getVector3fMap() = cloud.points().row(Eigen::Index(i)).transpose().cast<float>();
      p.getNormalVector3fMap() = cloud.normals().row(Eigen::Index(i)).transpose().cast<float>();
      p.curvature = 0.0f;
    }
    pcl::toPCLPointCloud2(pcl_cloud, message);
  } else {
    pcl::PointCloud<pcl::PointXYZ> pcl_cloud;
    pcl_cloud.resize(cloud.size());
    for (std::size_t i = 0; i < cloud.size(); ++i) {
      pcl_cloud[i].getVector3fMap() = cloud.points().row(Eigen::Index(i)).transpose().cast<float>();
    }
    pcl::toPCLPointCloud2(pcl_cloud, message);
  }
  int status = -1;
  try {
    if (format == Format::ply) {
      pcl::PLYWriter writer;
      status = writer.writeBinary(path, message);
    } else {
      pcl::PCDWriter writer;
      switch (encoding) {
        case PcdEncoding::ascii:
          status = writer.writeASCII(path, message);
          break;
        case PcdEncoding::binary:
          status = writer.writeBinary(path, message);
          break;
        case PcdEncoding::binary_compressed:
          status = writer.writeBinaryCompressed(path, message);
          break;
      }
    }
  } catch (const std::exception& error) {
    fail("path: cannot write ", path, ": ", error.what());
  }
  if (status < 0) {
    fail("path: cannot write ", path);
  }
}

}  // namespace spectral_vs
