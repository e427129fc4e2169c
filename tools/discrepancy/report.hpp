#pragma once
/// The discrepancy workflow's outputs: report.json (fields as the issue lists them),
/// model.toml, report.html with inline SVG plots drawn by this code.

#include <string>

#include "tools/discrepancy/workflow.hpp"

namespace pumptherm::tools::discrepancy {

/// What report.html shows beyond the Result; every member may be left empty.
struct ReportContext {
  /// The input model as model.toml writes it without effects (ApplyModelEffects with none), so
  /// report.html can show the edit line by line; "" = the edit is not shown.
  std::string input_model_toml;
  /// The decision rule's thresholds the run used, for the "why not named" column.
  Options options;
  /// The validation data, for the input strip (speed, current) and the residuals' correlation
  /// with the inputs; nullptr = neither is drawn.
  const Data* validate = nullptr;
};

/// report.json text.
std::string ReportJson(const Result& r, const std::string& model, const std::string& train,
                       const std::string& validate);

/// report.html text: the story, measured against simulated per node before and after, the
/// residuals, the candidate ranking.
std::string ReportHtml(const Result& r, const std::string& model, const std::string& train,
                       const std::string& validate, const ReportContext& context = {});

/// Writes report.json, model.toml and report.html into `dir` (created if missing). Throws
/// std::system_error when a file cannot be written.
void WriteReport(const std::string& dir, const Result& r, const std::string& model,
                 const std::string& train, const std::string& validate,
                 const ReportContext& context = {});

}  // namespace pumptherm::tools::discrepancy
