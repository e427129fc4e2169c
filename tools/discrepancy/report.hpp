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

/// The report's first line: is the model (with the effects added) right now, by the residual
/// tests on the validation data (docs/discrepancy.md, "Residual tests").
struct ModelRightNow {
  /// "yes" (every tested node passes every test), "not yet" (a test fails), "untested" (no node
  /// has the 8 validation points the tests need).
  std::string answer;
  /// One line: "Model right now: not yet: frame's residual is not white (fails at lags ...)
  /// after adding frame_ambient_resistance; fit 90.2 %, RMSE 0.743 K" and what that means.
  std::string line;
};

/// The answer from the after-effects residuals of `r.validate_plot`; the cross-correlation
/// tests need `context.validate` (without it only whiteness is tested, and the line says so).
ModelRightNow CheckModelRightNow(const Result& r, const ReportContext& context = {});

/// report.json text; `context` as for ReportHtml (its validation data give the residual tests'
/// inputs).
std::string ReportJson(const Result& r, const std::string& model, const std::string& train,
                       const std::string& validate, const ReportContext& context = {});

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
