#pragma once
// Hidden-effect cases shared by the discrepancy tests and the benchmark: the Saheba 2010 baseline
// model as the workflow's model, data from it (or from saheba2010-improved, the paper's case)
// with an effect switched on that the workflow is not told about.
#include <string>

#include "tests/common/test_files.hpp"
#include "tools/discrepancy/hidden_data.hpp"

namespace pumptherm::tests {

/// Train and validation data (different load profiles and noise) for a truth model with
/// `hidden` effects. Short data at coarse steps: `hours` at `step_s`.
inline std::pair<tools::discrepancy::Data, tools::discrepancy::Data> HiddenCase(
    const std::string& truth_model, const std::vector<estimators::Effect>& hidden,
    double hours = 8.0, double step_s = 10.0, std::uint64_t seed = 1) {
  tools::discrepancy::HiddenDataConfig c;
  c.model_text = test_files::ReadModel(truth_model);
  c.model_source = truth_model;
  c.hidden = hidden;
  c.duration_s = hours * 3600.0;
  c.step_s = step_s;
  c.profile_seed = seed;
  c.noise_seed = seed + 100;
  auto train = tools::discrepancy::MakeHiddenEffectData(c);
  c.profile_seed = seed + 1000;
  c.noise_seed = seed + 2000;
  auto validate = tools::discrepancy::MakeHiddenEffectData(c);
  return {std::move(train), std::move(validate)};
}

}  // namespace pumptherm::tests
