#pragma once
/// The discrepancy workflow's outputs (issue 7): report.json (fields as the issue lists them),
/// model.toml, report.html with inline SVG plots drawn by this code.

#include <string>

#include "tools/discrepancy/workflow.hpp"

namespace pumptherm::tools::discrepancy {

/// report.json text.
std::string ReportJson(const Result& r, const std::string& model, const std::string& train,
                       const std::string& validate);

/// report.html text: the story, measured against simulated per node before and after, the
/// residuals, the candidate ranking.
std::string ReportHtml(const Result& r, const std::string& model, const std::string& train,
                       const std::string& validate);

/// Writes report.json, model.toml and report.html into `dir` (created if missing). Throws
/// std::system_error when a file cannot be written.
void WriteReport(const std::string& dir, const Result& r, const std::string& model,
                 const std::string& train, const std::string& validate);

}  // namespace pumptherm::tools::discrepancy
