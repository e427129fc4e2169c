#pragma once
/// Finding and loading thermal model files for the `simulate`, `estimate`, `placement` and
/// `plant` subcommands. A model argument is a path to a .toml file, or the name of a shipped model
/// (`saheba2010-improved`), found as the daemon finds it (daemon/resources.hpp).

#include <fmt/core.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "daemon/resources.hpp"
#include "estimators/thermal_model.hpp"
#include "tools/pumptherm/subcommand.hpp"

namespace pumptherm::tools {

/// Resolves `model` (a path, or a shipped model's name) to a file path with the daemon's
/// resolver (daemon/resources.hpp), so tools and daemon find the same files; throws InputError
/// listing where it looked.
inline std::string ResolveModelPath(const std::string& model) {
  try {
    return daemon::ResolveResource(daemon::ResourceKind::kModel, model);
  } catch (const std::runtime_error& e) {
    throw InputError(fmt::format("model {}", e.what()));
  }
}

/// Reads and parses a model; model-file errors become InputError (exit code 2).
inline estimators::ThermalModel LoadThermalModel(const std::string& model) {
  const std::string path = ResolveModelPath(model);
  std::ifstream f(path);
  if (!f) throw InputError(fmt::format("cannot read model file '{}'", path));
  std::stringstream ss;
  ss << f.rdbuf();
  try {
    // Tables the model names (loss maps, curves) are read relative to the model file.
    return estimators::ThermalModel::Parse(
        ss.str(), path, estimators::ThermalModelFiles{daemon::DirectoryOf(path), &daemon::ReadTextFile});
  } catch (const estimators::ThermalModelError& e) {
    throw InputError(e.what());
  }
}

}  // namespace pumptherm::tools
