#include "daemon/resources.hpp"

#include <fmt/format.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <vector>

namespace pumptherm::daemon {
namespace fs = std::filesystem;

namespace {

struct KindInfo {
  const char* share_dir;    // under share/pumptherm
  const char* source_dir;   // under the source tree
  const char* extension;
};

KindInfo Info(ResourceKind kind) {
  switch (kind) {
    case ResourceKind::kModel: return {"models", "estimators/models", ".toml"};
    case ResourceKind::kMotor: return {"motors", "estimators/motors", ".toml"};
    case ResourceKind::kDbc: return {"dbc", "protocol", ""};
  }
  return {"", "", ""};
}

}  // namespace

std::string DirectoryOf(const std::string& path) {
  const fs::path p(path);
  return p.has_parent_path() ? p.parent_path().string() : ".";
}

std::string ResolveResource(ResourceKind kind, const std::string& reference,
                            const std::string& base_dir) {
  const KindInfo info = Info(kind);
  const bool is_path = reference.find('/') != std::string::npos || reference.ends_with(".toml") ||
                       reference.ends_with(".dbc");
  std::vector<fs::path> candidates;
  if (is_path) {
    const fs::path p(reference);
    candidates.push_back(p.is_absolute() ? p : fs::path(base_dir) / p);
  }
  // A bare file name of a shipped file (e.g. "pumptherm.dbc") is also looked up below.
  if (!is_path || reference.find('/') == std::string::npos) {
    const std::string file = reference.ends_with(info.extension) || !*info.extension
                                 ? reference
                                 : reference + info.extension;
    std::error_code ec;
    const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
    if (!ec) candidates.push_back(exe.parent_path() / ".." / "share" / "pumptherm" / info.share_dir / file);
    candidates.push_back(fs::path(PUMPTHERM_INSTALL_DATADIR) / "pumptherm" / info.share_dir / file);
    candidates.push_back(fs::path(PUMPTHERM_SOURCE_DIR) / info.source_dir / file);
  }
  std::string tried;
  for (const fs::path& c : candidates) {
    std::error_code ec;
    if (fs::is_regular_file(c, ec)) return c.lexically_normal().string();
    tried += "\n  " + c.lexically_normal().string();
  }
  throw std::runtime_error(fmt::format("'{}': no such {} file; looked for:{}", reference,
                                       info.share_dir, tried));
}

std::string ReadTextFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::runtime_error(fmt::format("{}: cannot open: {}", path, std::strerror(errno)));
  std::ostringstream ss;
  ss << in.rdbuf();
  if (in.bad()) throw std::runtime_error(fmt::format("{}: cannot read: {}", path, std::strerror(errno)));
  return ss.str();
}

}  // namespace pumptherm::daemon
