#include "shipped/shipped_files.hpp"

#include <fmt/format.h>

#include <cctype>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string_view>

namespace pumptherm::shipped {
namespace fs = std::filesystem;

namespace {

struct KindInfo {
  const char* share_dir;   // under share/pumptherm
  const char* source_dir;  // under the source tree
  const char* extension;   // added to a bare name; "" keeps the name as given
};

KindInfo Info(FileKind kind) {
  switch (kind) {
    case FileKind::kModel:
      return {"models", "estimators/models", ".toml"};
    case FileKind::kMotor:
      return {"motors", "estimators/motors", ".toml"};
    case FileKind::kDbc:
      return {"dbc", "protocol", ""};
    case FileKind::kScenario:
      return {"scenarios", "tools/plant/scenarios", ".toml"};
  }
  return {"", "", ""};
}

/// Whether `name` ends in `extension`, in any case (".DBC", ".Toml": files from other systems).
bool EndsWithNoCase(const std::string& name, std::string_view extension) {
  if (name.size() < extension.size()) return false;
  const std::string_view tail = std::string_view(name).substr(name.size() - extension.size());
  for (std::size_t i = 0; i < tail.size(); ++i) {
    if (std::tolower(static_cast<unsigned char>(tail[i])) != extension[i]) return false;
  }
  return true;
}

bool IsPath(const std::string& reference) {
  return reference.find('/') != std::string::npos || EndsWithNoCase(reference, ".toml") ||
         EndsWithNoCase(reference, ".dbc");
}

std::string WithExtension(const std::string& name, const char* extension) {
  return !*extension || name.ends_with(extension) ? name : name + extension;
}

}  // namespace

std::vector<std::string> SearchDirs(FileKind kind) {
  const KindInfo info = Info(kind);
  std::vector<std::string> dirs;
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  if (!ec)
    dirs.push_back(
        (exe.parent_path() / ".." / "share" / "pumptherm" / info.share_dir).lexically_normal());
  dirs.push_back(
      (fs::path(PUMPTHERM_INSTALL_DATADIR) / "pumptherm" / info.share_dir).lexically_normal());
  dirs.push_back((fs::path(PUMPTHERM_SOURCE_DIR) / info.source_dir).lexically_normal());
  return dirs;
}

std::string Resolve(FileKind kind, const std::string& reference, const std::string& base_dir) {
  const KindInfo info = Info(kind);
  std::vector<fs::path> candidates;
  // A file that exists is taken as a path whatever its name looks like ("issue_168.DBC", a model
  // without an extension); a reference that only looks like a path is reported as one.
  const fs::path as_path =
      fs::path(reference).is_absolute() ? fs::path(reference) : fs::path(base_dir) / reference;
  std::error_code exists_ec;
  if (IsPath(reference) || fs::is_regular_file(as_path, exists_ec)) candidates.push_back(as_path);
  if (reference.find('/') == std::string::npos) {
    const std::string file = WithExtension(reference, info.extension);
    for (const std::string& dir : SearchDirs(kind)) candidates.push_back(fs::path(dir) / file);
  }
  std::string tried;
  for (const fs::path& c : candidates) {
    std::error_code ec;
    if (fs::is_regular_file(c, ec)) return c.lexically_normal().string();
    tried += "\n  " + c.lexically_normal().string();
  }
  std::error_code dir_ec;
  if (fs::is_directory(as_path, dir_ec))
    throw FileNotFound(
        fmt::format("'{}': is a directory, not a {} file", as_path.string(), info.share_dir));
  throw FileNotFound(
      fmt::format("'{}': no such {} file; looked for:{}", reference, info.share_dir, tried));
}

std::string ReadTextFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::runtime_error(fmt::format("{}: cannot open: {}", path, std::strerror(errno)));
  std::ostringstream ss;
  ss << in.rdbuf();
  if (in.bad())
    throw std::runtime_error(fmt::format("{}: cannot read: {}", path, std::strerror(errno)));
  return ss.str();
}

std::string DirectoryOf(const std::string& path) {
  const fs::path p(path);
  return p.has_parent_path() ? p.parent_path().string() : ".";
}

}  // namespace pumptherm::shipped
