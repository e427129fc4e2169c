#pragma once
// Test helpers: where the shared real-world DBC files are, and reading a file whole.
#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "tests/common/test_files.hpp"

namespace pumptherm::protocol::test {

/// The repository root (CTest sets PUMPTHERM_SOURCE_DIR; tests also run from the root).
inline std::filesystem::path SourceDir() {
  const char* dir = std::getenv("PUMPTHERM_SOURCE_DIR");
  return dir != nullptr ? std::filesystem::path(dir) : std::filesystem::current_path();
}

/// ../shared/data/dbc next to the repository (absent on checkouts outside the team's machines);
/// PUMPTHERM_SHARED_DIR names another copy of shared/ (a git worktree sits elsewhere).
inline std::filesystem::path SharedDbcDir() {
  const char* shared = std::getenv("PUMPTHERM_SHARED_DIR");
  const std::filesystem::path root =
      shared != nullptr ? std::filesystem::path(shared) : SourceDir() / ".." / "shared";
  return root / "data" / "dbc";
}

/// Every *.dbc under SharedDbcDir(), sorted; empty if the folder is absent.
inline std::vector<std::filesystem::path> RealDbcFiles() {
  std::vector<std::filesystem::path> out;
  std::error_code ec;
  if (!std::filesystem::is_directory(SharedDbcDir(), ec)) return out;
  for (const auto& e : std::filesystem::recursive_directory_iterator(SharedDbcDir())) {
    if (e.is_regular_file() && e.path().extension() == ".dbc") out.push_back(e.path());
  }
  std::sort(out.begin(), out.end());
  return out;
}

/// The project's own frame set.
inline std::filesystem::path PumpthermDbc() { return SourceDir() / "protocol" / "pumptherm.dbc"; }

using pumptherm::test_files::ReadFile;

}  // namespace pumptherm::protocol::test
