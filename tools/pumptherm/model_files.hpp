#pragma once
/// Finding and loading thermal model files for the `simulate`, `estimate` and `placement`
/// subcommands. A model argument is a path to a .toml file, or the name of a shipped model
/// (`saheba2010-improved`), looked up in <exe>/../share/pumptherm/models (an installed tree),
/// then in the configured install directory, then in the source tree's estimators/models (a build
/// tree). Both directories come from compile definitions set in tools/CMakeLists.txt.

#include <fmt/core.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "estimators/thermal_model.hpp"
#include "tools/pumptherm/subcommand.hpp"

namespace pumptherm::tools {

/// Resolves `model` to a file path; throws InputError listing where it looked.
inline std::string ResolveModelPath(const std::string& model) {
  namespace fs = std::filesystem;
  if (model.find('/') != std::string::npos || model.ends_with(".toml")) {
    if (!fs::exists(model)) throw InputError(fmt::format("model file '{}' does not exist", model));
    return model;
  }
  std::vector<fs::path> dirs;
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  if (!ec) dirs.push_back(exe.parent_path() / ".." / "share" / "pumptherm" / "models");
  dirs.emplace_back(PUMPTHERM_MODELS_INSTALL_DIR);
  dirs.emplace_back(PUMPTHERM_MODELS_SOURCE_DIR);
  std::string tried;
  for (const fs::path& d : dirs) {
    const fs::path p = d / (model + ".toml");
    if (fs::exists(p)) return p.lexically_normal().string();
    tried += "\n  " + p.lexically_normal().string();
  }
  throw InputError(fmt::format("no shipped model named '{}'; looked for:{}", model, tried));
}

/// Reads and parses a model; model-file errors become InputError (exit code 2).
inline estimators::ThermalModel LoadThermalModel(const std::string& model) {
  const std::string path = ResolveModelPath(model);
  std::ifstream f(path);
  if (!f) throw InputError(fmt::format("cannot read model file '{}'", path));
  std::stringstream ss;
  ss << f.rdbuf();
  try {
    return estimators::ThermalModel::Parse(ss.str(), path);
  } catch (const estimators::ThermalModelError& e) {
    throw InputError(e.what());
  }
}

}  // namespace pumptherm::tools
