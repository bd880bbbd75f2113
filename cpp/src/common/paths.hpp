#pragma once
// What a path names, for the calls that read or write files: a folder, a FIFO (whose
// reader or writer would block) or a symbolic link loop is named as such, not as a
// missing file. One classification for the cloud files, the URDF and the bindings.

#include <filesystem>
#include <system_error>

namespace spectral_vs::detail {

enum class PathKind { file, missing, folder, special, loop };

inline PathKind path_kind(const std::filesystem::path& path) {
  std::error_code error;
  const auto status = std::filesystem::status(path, error);
  if (error == std::errc::too_many_symbolic_link_levels) return PathKind::loop;
  if (error || !std::filesystem::exists(status)) return PathKind::missing;
  if (std::filesystem::is_directory(status)) return PathKind::folder;
  if (!std::filesystem::is_regular_file(status)) return PathKind::special;
  return PathKind::file;
}

/// Why a path of this kind cannot be read as a file ("" for a file).
inline const char* path_problem(PathKind kind) {
  switch (kind) {
    case PathKind::missing:
      return "no such file";
    case PathKind::folder:
      return "is a folder, not a file";
    case PathKind::special:
      return "is not a regular file (a FIFO, socket or device)";
    case PathKind::loop:
      return "too many levels of symbolic links (a loop)";
    default:
      return "";
  }
}

}  // namespace spectral_vs::detail
