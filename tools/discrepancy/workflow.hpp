#pragma once
/// The model discrepancy workflow (statistics and decision rule in docs/discrepancy.md):
/// simulate a thermal model on measured inputs, measure the gap, fit every candidate effect of
/// the vocabulary (estimators/model_effects.hpp) on TRAIN with Ceres, score it on VALIDATE and
/// by an information criterion that allows for the autocorrelation of thermal residuals, name
/// the candidate that wins by a margin with a significant parameter, add it and repeat.

#include <functional>
#include <string>
#include <vector>

#include "estimators/model_effects.hpp"
#include "tools/discrepancy/data.hpp"

namespace pumptherm::tools::discrepancy {

struct Options {
  std::vector<std::string> effects;  ///< candidate effect names; empty = the whole vocabulary
  int max_effects = 3;
  /// Simulation grid: the residuals are taken at samples thinned to steps of at least
  /// min_grid_step_s and at most max_grid_points points. Data of at most max_exact_rows rows are
  /// simulated row by row (each row's inputs held until the next, as `pumptherm simulate`);
  /// longer data with the inputs averaged over each grid step (an approximation whose cost the
  /// result reports).
  double min_grid_step_s = 10.0;
  int max_grid_points = 2000;
  long max_exact_rows = 20000;
  // Decision rule (docs/discrepancy.md).
  double ic_threshold = 10.0;         ///< delta IC at least this far below the current model
  double min_validation_gain = 0.10;  ///< validation RMSE cut by at least this fraction
  /// The best eligible candidate is named unless a rival has a validation RMSE below
  /// (1 + margin) x the best's and is eligible itself, or the best's is not below the current
  /// model's by that margin either.
  double margin = 0.20;
  int max_fit_iterations = 30;
  /// Called with one line of progress (the command prints it on a terminal).
  std::function<void(const std::string&)> progress;
};

/// Gap between simulation and measurement on one data set.
struct NodeGap {
  std::string node;  ///< "overall" for all measured nodes together
  double rmse_K = 0.0;
  double max_abs_K = 0.0;
};

struct FittedParameter {
  std::string name;
  double value = 0.0, low95 = 0.0, high95 = 0.0, neutral = 0.0;
};

struct Candidate {
  std::string effect;
  std::string node;                         ///< sensor effects: the measured node
  std::string label;                        ///< effect or effect(node)
  std::string not_applicable;               ///< reason, when it was not tried
  std::vector<FittedParameter> parameters;  ///< the candidate's own parameters
  double train_rmse_K = 0.0, validate_rmse_K = 0.0;
  double rho = 0.0, n_eff = 0.0, delta_ic = 0.0;
  bool significant = false, eligible = false;
  int evaluations = 0;
};

struct Round {
  std::vector<Candidate> candidates;  ///< sorted by validation RMSE (tried ones first)
  std::string verdict;                ///< named, ambiguous, none
  std::vector<std::string> tied;      ///< ambiguous: labels that cannot be told apart
  std::string experiment;             ///< ambiguous: what would separate them
  double base_train_rmse_K = 0.0, base_validate_rmse_K = 0.0;
};

struct AddedEffect {
  estimators::Effect effect;
  std::vector<FittedParameter> parameters;
  std::string reading;
};

/// Series on the simulation grid for the plots (validation data).
struct PlotSeries {
  std::vector<double> time_s;
  std::vector<std::string> nodes;
  std::vector<std::vector<double>> measured, before, after;  ///< [node][k]
};

struct Result {
  std::string verdict;  ///< of the first round: named, ambiguous, none
  std::vector<AddedEffect> effects;
  std::vector<Round> rounds;
  std::vector<NodeGap> train_before, train_after, validate_before, validate_after;
  std::string model_toml;  ///< the input model with the effects added
  PlotSeries validate_plot, train_plot;
  double seconds = 0.0;
  /// "rows" (every data row, exact) or "averaged" (inputs averaged over grid steps); for
  /// averaged, the input model's RMSE between the averaged and the row-by-row simulation at the
  /// grid points, on train and on validation data: what the approximation costs.
  std::string simulation = "rows";
  double averaging_cost_train_K = 0.0, averaging_cost_validate_K = 0.0;
};

/// The workflow's simulation of `model` on `data` at its grid points (the same grid, start and
/// stepping as Run uses for its input model).
struct Simulated {
  std::vector<double> time_s;
  std::vector<std::string> nodes;               ///< the measured nodes
  std::vector<std::vector<double>> temps_degC;  ///< [node][point]
  bool averaged = false;
};
Simulated SimulateModel(const estimators::ThermalModel& model, const Data& data,
                        const Options& options);

/// Runs the workflow. `model_text` is the model file, `source` its name, `files` how the tables
/// it names are read (estimators/thermal_model.hpp); the model.toml of the result names those
/// tables by absolute path when `files.directory` is set. Throws estimators::ThermalModelError
/// for a bad model, std::invalid_argument for an unknown effect name in options or data without
/// a node of the model.
Result Run(const std::string& model_text, const std::string& source, const Data& train,
           const Data& validate, const Options& options,
           const estimators::ThermalModelFiles& files = {});

/// `toml` with every float value written in its shortest round-trip form (fmt's `{}`:
/// "0.00393", not toml++'s 17 digits "0.0039300000000000003"), still a float (".0" kept);
/// strings, comments, keys and integers unchanged. The same values, read back bit for bit.
std::string ShortestFloats(std::string_view toml);

/// What experiment separates these effects (one sentence per effect).
std::string SeparatingExperiment(const std::vector<std::string>& effects);

}  // namespace pumptherm::tools::discrepancy
