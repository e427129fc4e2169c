// report.html from a hand-made Result (no fit, no browser): where the ambiguity is stated, the
// digits of an interval, units, the why-not-named column, the model edit and the plots' ticks.
#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <random>
#include <string>
#include <vector>

#include "tools/discrepancy/report.hpp"
#include "tools/discrepancy/workflow.hpp"

namespace pd = pumptherm::tools::discrepancy;

namespace {

pd::Candidate Tried(const std::string& effect, const std::string& param, double v, double lo,
                    double hi, double validate_rmse_K, double delta_ic, bool significant,
                    bool eligible) {
  pd::Candidate c;
  c.effect = c.label = effect;
  c.parameters = {{param, v, lo, hi, 0.0}};
  c.validate_rmse_K = validate_rmse_K;
  c.train_rmse_K = validate_rmse_K;
  c.delta_ic = delta_ic;
  c.rho = 0.9;
  c.n_eff = 20;
  c.significant = significant;
  c.eligible = eligible;
  return c;
}

// Round 1 names frame_ambient_resistance; round 2 cannot tell two candidates apart.
pd::Result TwoRounds() {
  pd::Result r;
  r.verdict = "named";
  pd::AddedEffect e;
  e.effect.name = "frame_ambient_resistance";
  e.parameters = {{"frame_resistance_scale", 1.2034, 1.2014, 1.2054, 1.0}};
  e.reading = "frame cooling worse than modelled";
  r.effects = {e};
  pd::Round r1;
  r1.verdict = "named";
  r1.base_validate_rmse_K = 2.0;
  r1.candidates = {Tried("frame_ambient_resistance", "frame_resistance_scale", 1.2034, 1.2014,
                         1.2054, 0.2, -300, true, true),
                   Tried("frame_thermal_mass", "frame_extra_capacity_J_per_K", 2500, -400, 5400,
                         1.9, -3.0, false, false)};
  pd::Round r2;
  r2.verdict = "ambiguous";
  r2.base_validate_rmse_K = 0.2;
  r2.tied = {"rotor_loss", "iron_loss_scale"};
  r2.experiment = "the same losses at two speeds";
  r2.candidates = {
      Tried("rotor_loss", "rotor_loss_W_per_krpm2", 3.0, 2.0, 4.0, 0.15, -20, true, true),
      Tried("iron_loss_scale", "iron_loss_scale", 1.3, 1.2, 1.4, 0.16, -18, true, true)};
  r.rounds = {r1, r2};
  for (auto* g : {&r.train_before, &r.train_after, &r.validate_before, &r.validate_after})
    *g = {{"overall", 1.0, 2.0}};
  r.model_toml =
      "[parameters]\na = 1\nframe_resistance_scale = 1.2034\n\n[[edge]]\nresistance_K_per_W = "
      "'frame_resistance_scale * 0.5'\n";
  r.validate_plot.time_s = {0.0, 1800.0, 3600.0, 5400.0, 7200.0};
  r.validate_plot.nodes = {"frame"};
  r.validate_plot.measured = {{20.0, 24.0, 27.0, 28.5, 29.0}};
  r.validate_plot.before = {{20.0, 23.0, 25.0, 26.0, 26.5}};
  r.validate_plot.after = {{20.0, 24.1, 27.1, 28.4, 29.0}};
  return r;
}

}  // namespace

TEST(DiscrepancyReport, AmbiguityInItsRoundIntervalDigitsUnitsAndWhyNot) {
  pd::ReportContext ctx;
  ctx.input_model_toml = "[parameters]\na = 1\n\n[[edge]]\nresistance_K_per_W = '0.5'\n";
  const std::string h = pd::ReportHtml(TwoRounds(), "m.toml", "t.csv", "v.csv", ctx);
  const std::size_t round1 = h.find("Round 1: named"), round2 = h.find("Round 2: ambiguous");
  const std::size_t amb = h.find("Cannot tell apart");
  ASSERT_NE(round1, std::string::npos);
  ASSERT_NE(round2, std::string::npos);
  ASSERT_NE(amb, std::string::npos);
  EXPECT_GT(amb, round2) << "the ambiguity must be stated under the round it came from";
  EXPECT_EQ(h.find("Cannot tell apart", amb + 1), std::string::npos);
  // Width 0.004: three significant figures of it need five decimals.
  EXPECT_NE(h.find("1.20340 (95 % 1.20140 to 1.20540)"), std::string::npos);
  EXPECT_NE(h.find("2500 (95 % -400 to 5400) J/K"), std::string::npos);
  EXPECT_NE(h.find("W/(1000 r/min)^2"), std::string::npos);
  EXPECT_NE(h.find("not significant (interval includes 0); dIC -3.0 &gt; -10; validation gain 5.0 "
                   "% &lt; 10 %"),
            std::string::npos);
  EXPECT_NE(h.find("within the 20 % margin of the best: cannot tell apart"), std::string::npos);
  EXPECT_NE(h.find("<span class='del'>- resistance_K_per_W = '0.5'</span>"), std::string::npos);
  EXPECT_NE(
      h.find("<span class='add'>+ resistance_K_per_W = 'frame_resistance_scale * 0.5'</span>"),
      std::string::npos);
  EXPECT_NE(h.find("<a href='model.toml'>"), std::string::npos);
  EXPECT_NE(h.find("<a href='report.json'>"), std::string::npos);
  // Time axis of 2 h in round ticks (0.0, 0.5, ... 2.0), the residual plot's zero line.
  EXPECT_NE(h.find(">0.5</text>"), std::string::npos);
  EXPECT_NE(h.find(">2.0</text>"), std::string::npos);
  EXPECT_NE(h.find("stroke='#000' stroke-width='0.8'"), std::string::npos);
}

TEST(DiscrepancyReport, ModelFilesInShortestRoundTripForm) {
  const std::string toml =
      "[parameters]\nalpha_cu_per_K = 0.0041000000000000003\nke_W_s2 = 9.0000000000000006e-05\n"
      "rated_rpm = 21000\nspeed = 21000.0\nr1 = -0.34999999999999998 # a comment "
      "0.10000000000000001\n"
      "name = '0.10000000000000001'\nlist = [ 1.0, 2.5000000000000004 ]\n";
  EXPECT_EQ(pd::ShortestFloats(toml),
            "[parameters]\nalpha_cu_per_K = 0.0041\nke_W_s2 = 9e-05\nrated_rpm = 21000\n"
            "speed = 21000.0\nr1 = -0.35 # a comment 0.10000000000000001\n"
            "name = '0.10000000000000001'\nlist = [ 1.0, 2.5000000000000004 ]\n");
}

TEST(DiscrepancyReport, IntervalsClippedOrUnidentifiableAndRoundingThatAgreesWithTheRule) {
  pd::Result r = TwoRounds();
  // The case: a lag whose interval spans more than its whole range (0 to 3600 s).
  r.rounds[0].candidates.push_back(
      Tried("sensor_lag", "sensor_lag_s", 0.0, -2203.77, 2203.77, 1.995, 0.7, false, false));
  // An interval past the scale's lower bound (0.05): clipped to it.
  r.rounds[0].candidates.push_back(Tried("frame_ambient_resistance", "frame_resistance_scale", 0.4,
                                         -0.1, 0.9, 1.8008, -12, true, false));
  r.rounds[0].candidates.back().label = "frame_ambient_resistance (another fit)";
  const std::string h = pd::ReportHtml(r, "m.toml", "t.csv", "v.csv", {});
  EXPECT_NE(h.find("sensor_lag_s = 0 s (unidentifiable: the data do not determine it)"),
            std::string::npos)
      << h;
  EXPECT_NE(h.find("0.400 (95 % 0.050 to 0.900, clipped to the physical range)"), std::string::npos)
      << h;
  // A gain of 9.96 % is not printed as 10.0 % against its 10 % threshold.
  EXPECT_NE(h.find("validation gain 9.96 % &lt; 10 %"), std::string::npos) << h;
}

TEST(DiscrepancyReport, ResidualTestsBeforeAndAfterWithTheirLags) {
  // Two hours at 10 s: the "before" residual is the current (a missed loss the input drives),
  // the "after" residual a small deterministic wobble the current does not drive.
  pd::Result r = TwoRounds();
  pd::Data d;
  pd::PlotSeries& v = r.validate_plot;
  v.time_s.clear();
  v.measured = v.before = v.after = {{}};
  for (int k = 0; k < 720; ++k) {
    const double t = 10.0 * k;
    const double current = (k / 90) % 2 == 0 ? 1.0 : 4.0;
    const double noise = 0.05 * std::sin(12.9898 * k) * std::cos(78.233 * k);
    v.time_s.push_back(t);
    v.measured[0].push_back(40.0 + 2.0 * current);
    v.before[0].push_back(40.0 + 2.0 * current - 0.5 * current);
    v.after[0].push_back(40.0 + 2.0 * current + noise);
    d.time_s.push_back(t);
    d.speed_rpm.push_back(21000.0 + (k % 7));
    d.id_A.push_back(0.0);
    d.iq_A.push_back(current);
    d.ambient_degC.push_back(22.0);
    d.coolant_degC.push_back(22.0);
  }
  pd::ReportContext ctx;
  ctx.validate = &d;
  const std::string h = pd::ReportHtml(r, "m.toml", "t.csv", "v.csv", ctx);
  const std::size_t tests = h.find("Is the model right now?");
  ASSERT_NE(tests, std::string::npos);
  const std::string table = h.substr(tests, h.find("</table>", tests) - tests);
  EXPECT_NE(table.find("<td>x current</td><td class='why fail'>FAILS at lags"), std::string::npos)
      << table;
  EXPECT_NE(table.find("99.2 %, 0.025 K"), std::string::npos) << "the after fit:\n" << table;
  EXPECT_NE(table.find("<td>x current</td><td class='why fail'>FAILS at lags -2.2 to 2.2 min (peak "
                       "1.00 at 0.0 min, band 0.72)</td><td class='why pass'>passes"),
            std::string::npos)
      << table;
  EXPECT_EQ(table.find("x ambient"), std::string::npos) << "a constant ambient is not tested";
  // The inputs are shown, the ambient included; the legend gives each curve's fit and RMSE.
  EXPECT_NE(h.find(">input: ambient</text>"), std::string::npos);
  EXPECT_NE(h.find("after: fit 99.2 %, RMSE 0.03 K"), std::string::npos);
  EXPECT_NE(h.find("frame before: residual x current"), std::string::npos);
  EXPECT_NE(h.find("frame after: residual autocorrelation"), std::string::npos);
}

namespace {

// Two hours at 10 s of one node, the current stepping 1 A / 4 A every 15 min; the "after"
// residual is `after_residual(k, current)`. The validation inputs in `d`.
constexpr unsigned kWhiteSeed = 6;

pd::Result OneNode(pd::Data& d, const std::function<double(int, double)>& after_residual) {
  pd::Result r = TwoRounds();
  pd::PlotSeries& v = r.validate_plot;
  v.time_s.clear();
  v.measured = v.before = v.after = {{}};
  d = {};
  for (int k = 0; k < 720; ++k) {
    const double t = 10.0 * k;
    const double current = (k / 90) % 2 == 0 ? 1.0 : 4.0;
    v.time_s.push_back(t);
    v.measured[0].push_back(40.0 + 2.0 * current);
    v.before[0].push_back(40.0 + 1.5 * current);
    v.after[0].push_back(40.0 + 2.0 * current + after_residual(k, current));
    d.time_s.push_back(t);
    d.speed_rpm.push_back(21000.0 + (k % 7));
    d.id_A.push_back(0.0);
    d.iq_A.push_back(current);
    d.ambient_degC.push_back(22.0);
    d.coolant_degC.push_back(22.0);
  }
  return r;
}

/// OneNode with white residuals after the effects: uniform noise of +-0.05 K from std::mt19937
/// (its sequence is fixed by the standard) with `seed`.
pd::Result WhiteResiduals(pd::Data& d, unsigned seed) {
  std::mt19937 gen(seed);
  std::vector<double> noise;
  for (int k = 0; k < 720; ++k) noise.push_back(0.1 * (gen() / 4294967296.0 - 0.5));
  return OneNode(d, [&](int k, double) { return noise[static_cast<std::size_t>(k)]; });
}

}  // namespace

// The report's first line answers "is the model right now?" from the residual tests after the
// effects; report.json and the page say the same.
TEST(DiscrepancyReport, ModelRightNowYesWhenEveryTestPasses) {
  pd::Data d;
  // Seed 6: a sample that passes all three tests.
  const pd::Result r = WhiteResiduals(d, kWhiteSeed);
  pd::ReportContext ctx;
  ctx.validate = &d;
  const pd::ModelRightNow m = pd::CheckModelRightNow(r, ctx);
  EXPECT_EQ(m.answer, "yes") << m.line;
  EXPECT_EQ(m.line.rfind("Model right now: yes: every tested node passes whiteness and "
                         "cross-correlation with speed, current on the validation data after "
                         "adding frame_ambient_resistance; frame: fit ",
                         0),
            0u)
      << m.line;
  // RMSE of uniform noise of width 0.1 K: 0.1 / sqrt(12) = 0.0289 K; this sample 0.028 K.
  EXPECT_NE(m.line.find("frame: fit 99.1 %, RMSE 0.028 K"), std::string::npos) << m.line;
  const std::string h = pd::ReportHtml(r, "m.toml", "t.csv", "v.csv", ctx);
  const std::size_t first = h.find("Model right now: yes");
  ASSERT_NE(first, std::string::npos);
  EXPECT_LT(first, h.find("<h1>")) << "the answer comes before everything else";
  const std::string json = pd::ReportJson(r, "m.toml", "t.csv", "v.csv", ctx);
  EXPECT_NE(json.find("\"model_right_now\": {\"answer\": \"yes\", \"line\": \"" + m.line + "\""),
            std::string::npos)
      << json.substr(0, 800);
}

// A right model (white residuals) passes: each test holds its lags together at 95 %, so all
// three pass in most samples. With each lag at 95 % instead, 2 of seeds 1-39 did.
TEST(DiscrepancyReport, ModelRightNowYesForMostSamplesOfWhiteResiduals) {
  int yes = 0;
  for (unsigned seed = 1; seed <= 40; ++seed) {
    pd::Data d;
    const pd::Result r = WhiteResiduals(d, seed);
    pd::ReportContext ctx;
    ctx.validate = &d;
    if (pd::CheckModelRightNow(r, ctx).answer == "yes") ++yes;
  }
  RecordProperty("white_samples_passed_of_40", yes);
  EXPECT_GE(yes, 32) << "of 40 samples of white residuals";
  EXPECT_LT(yes, 40) << "a test that never fails a right model tests nothing";
}

TEST(DiscrepancyReport, ModelRightNowNotYetNamesTheNodeTheTestAndItsLags) {
  pd::Data d;
  // A loss the model still misses: the residual follows the current.
  const pd::Result r = OneNode(d, [](int, double current) { return -0.3 * current; });
  pd::ReportContext ctx;
  ctx.validate = &d;
  const pd::ModelRightNow m = pd::CheckModelRightNow(r, ctx);
  EXPECT_EQ(m.answer, "not yet") << m.line;
  EXPECT_NE(m.line.find("Model right now: not yet: frame's residual follows the current (fails "
                        "at lags -2.2 to 2.2 min; peak 1.00, band 0.72)"),
            std::string::npos)
      << m.line;
  EXPECT_NE(m.line.find("after adding frame_ambient_resistance; frame: fit "), std::string::npos)
      << m.line;
  EXPECT_NE(m.line.find("an input still drives the residual"), std::string::npos) << m.line;
  const std::string json = pd::ReportJson(r, "m.toml", "t.csv", "v.csv", ctx);
  EXPECT_NE(json.find("\"answer\": \"not yet\""), std::string::npos);
  EXPECT_NE(json.find("{\"test\": \"x current\", \"pass\": false, \"failing_lags_min\": [-2.16667"),
            std::string::npos)
      << json.substr(0, 1500);
  const std::string h = pd::ReportHtml(r, "m.toml", "t.csv", "v.csv", ctx);
  EXPECT_LT(h.find("<p class='now fail'><b>Model right now: not yet"), h.find("<h1>"));
  // Without the validation inputs only whiteness can be tested, and the line says so.
  const pd::ModelRightNow w = pd::CheckModelRightNow(r, {});
  EXPECT_NE(w.line.find("cross-correlation not tested: no validation inputs given"),
            std::string::npos)
      << w.line;
  // Too few points for any test.
  pd::Result few = TwoRounds();
  EXPECT_EQ(pd::CheckModelRightNow(few, ctx).answer, "untested");
}
