#pragma once
/// Finding and loading thermal model files (for `simulate`, `estimate`, `placement`, `plant`,
/// `discrepancy`) and motor descriptions (for `identify`, `telemetry`). A model argument is a path
/// to a .toml file, or the name of a shipped model (`saheba2010-improved`), found as the daemon
/// finds it (shipped/shipped_files.hpp); a motor argument is a built-in preset's name, a shipped
/// motor's name or a path.

#include <fmt/core.h>
#include <fmt/format.h>

#include <stdexcept>
#include <string>

#include "estimators/motor.hpp"
#include "estimators/thermal_model.hpp"
#include "shipped/shipped_files.hpp"
#include "tools/pumptherm/subcommand.hpp"

namespace pumptherm::tools {

/// Resolves `model` (a path, or a shipped model's name) to a file path with the search order the
/// daemon uses too (shipped/shipped_files.hpp); throws InputError listing where it looked.
inline std::string ResolveModelPath(const std::string& model) {
  try {
    return shipped::Resolve(shipped::FileKind::kModel, model);
  } catch (const shipped::FileNotFound& e) {
    throw InputError(fmt::format("model {}", e.what()));
  }
}

/// Reads and parses a model; model-file errors become InputError (exit code 2).
inline estimators::ThermalModel LoadThermalModel(const std::string& model) {
  const std::string path = ResolveModelPath(model);
  std::string text;
  try {
    text = shipped::ReadTextFile(path);
  } catch (const std::runtime_error& e) {
    throw InputError(fmt::format("cannot read model file: {}", e.what()));
  }
  try {
    // Tables the model names (loss maps, curves) are read relative to the model file.
    const estimators::ThermalModelFiles files{shipped::DirectoryOf(path), &shipped::ReadTextFile};
    return estimators::ThermalModel::Parse(text, path, files);
  } catch (const estimators::ThermalModelError& e) {
    throw InputError(e.what());
  }
}

/// A motor description: a built-in preset (estimators/motor.hpp), else a shipped motor's name or
/// a path. Throws InputError naming the reference, where it looked and the presets.
inline estimators::MotorDescription LoadMotor(const std::string& reference) {
  try {
    if (!estimators::MotorPresetText(reference).empty()) return estimators::MotorPreset(reference);
    const std::string path = shipped::Resolve(shipped::FileKind::kMotor, reference);
    return estimators::ParseMotorDescription(shipped::ReadTextFile(path), path);
  } catch (const estimators::MotorDescriptionError& e) {
    throw InputError(e.what());
  } catch (const std::runtime_error& e) {
    throw InputError(fmt::format("motor {} (presets: {})", e.what(),
                                 fmt::join(estimators::MotorPresetNames(), ", ")));
  }
}

}  // namespace pumptherm::tools
