// report.html from a hand-made Result (no fit, no browser): where the ambiguity is stated, the
// digits of an interval, units, the why-not-named column, the model edit and the plots' ticks.
#include <gtest/gtest.h>

#include <string>

#include "tools/discrepancy/report.hpp"

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
