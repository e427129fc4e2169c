#include "estimators/alarm_bounds.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <stdexcept>

#include "estimators/alarm_values.hpp"
#include "tests/estimators/one_node_model.hpp"

namespace pumptherm::estimators {
namespace {

constexpr double kNoReading = std::numeric_limits<double>::quiet_NaN();

using test::kOneNode;

double Closed(double t0_degC, double ambient_degC, double p_W, double t_s) {
  return ambient_degC + p_W + (t0_degC - ambient_degC - p_W) * std::exp(-t_s / 100.0);
}

ThermalInputs Load(double iq_A) {
  ThermalInputs in;
  in.iq_A = iq_A;
  in.ambient_degC = in.coolant_degC = 20.0;
  return in;
}

TEST(LagBias, RiseOverTheLagIsTheFirstOrderLagOfARamp) {
  // A sensor with lag tau on a node rising at r: after the transient y = T - tau r, and
  // y(t) - y(t - tau) = tau r.
  const double tau_s = 30.0, r_K_per_s = 0.05;
  LagBias bias(tau_s, 1.0);
  double y = 50.0, t_degC = 50.0, last = 0.0;
  for (int k = 0; k < 600; ++k) {
    t_degC += r_K_per_s;
    y += (t_degC - y) * (1.0 - std::exp(-1.0 / tau_s));  // exact step of the lag for T held
    last = bias.Step(y);
  }
  EXPECT_NEAR(last, t_degC - y, 0.05) << "bias " << last << ", true lag " << t_degC - y;
  EXPECT_NEAR(last, tau_s * r_K_per_s, 0.05);
}

TEST(LagBias, CoolingUnknownAndNoLagGiveZero) {
  LagBias bias(3.0, 1.0);
  for (double y : {60.0, 59.0, 58.0}) EXPECT_EQ(bias.Step(y), 0.0);  // 3 steps ago: not known yet
  EXPECT_EQ(bias.Step(57.0), 0.0);        // against 60: cooling, the safe side
  EXPECT_EQ(bias.Step(kNoReading), 0.0);  // no reading
  EXPECT_EQ(bias.Step(70.0), 12.0);       // against 58
  EXPECT_EQ(bias.Step(72.0), 15.0);       // against 57
  EXPECT_EQ(bias.Step(73.0), 0.0);        // against the missing reading
  LagBias none(0.0, 1.0);
  EXPECT_EQ(none.Step(80.0), 0.0);
  EXPECT_THROW(LagBias(-1.0, 1.0), std::invalid_argument);
  EXPECT_THROW(LagBias(1.0, 0.0), std::invalid_argument);
}

struct SilenceFixture {
  std::shared_ptr<const ThermalModel> model =
      std::make_shared<ThermalModel>(ThermalModel::Parse(kOneNode, "one"));
  SilenceBound bound;
  Eigen::VectorXd x = Eigen::VectorXd::Constant(1, 30.0);
  Eigen::VectorXd sd = Eigen::VectorXd::Constant(1, 0.5);
  double t_s = 0.0;
  void Step(double iq_A, bool fresh) {
    bound.Step(*model, Load(iq_A), fresh, x, sd, t_s += 1.0, 1.0, 2.0, 2.0);
  }
};

TEST(SilenceBound, ReRunsTheSilenceAtTheWorseLoad) {
  SilenceFixture f;
  f.Step(1.0, true);  // estimate 30 degC at 1 A (2 W): the last step before the silence
  for (int k = 0; k < 59; ++k) f.Step(1.0, false);  // 59 silent steps at the held 1 A
  f.x(0) = 25.0;                                    // the estimate that ran on at 1 A
  f.Step(3.0, true);                                // back, at 3 A (18 W)
  ASSERT_EQ(f.bound.bound_degC().size(), 1);
  // The truth can have run 3 A for the 59 silent steps and this one: 60 s from 30 degC.
  EXPECT_NEAR(f.bound.bound_degC()(0), Closed(30.0, 20.0, 18.0, 60.0), 1e-6);
}

TEST(SilenceBound, RunsOnAtTheLiveLoadAndEndsBelowTheUpperBound) {
  SilenceFixture f;
  f.Step(1.0, true);
  for (int k = 0; k < 9; ++k) f.Step(1.0, false);
  f.x(0) = 25.0;  // 10 s later: the bound (29.8 degC at 8 W) lies above 25 + 2 x 0.5
  f.Step(2.0, true);
  ASSERT_EQ(f.bound.bound_degC().size(), 1);
  const double b0 = f.bound.bound_degC()(0);
  f.x(0) = 26.0;
  f.Step(2.0, true);
  ASSERT_EQ(f.bound.bound_degC().size(), 1);
  EXPECT_NEAR(f.bound.bound_degC()(0), Closed(b0, 20.0, 8.0, 1.0), 1e-9);
  f.x(0) = f.bound.bound_degC()(0);  // the estimate has caught up: the bound ends
  f.Step(2.0, true);
  EXPECT_EQ(f.bound.bound_degC().size(), 0);
}

TEST(SilenceBound, TheSilenceIsTimedByTheStepsEndsNotCounted) {
  // Offline, a long gap in a log runs as one step: the bound still re-runs all of it.
  SilenceFixture f;
  f.Step(1.0, true);  // ends at 1 s
  f.x(0) = 25.0;
  f.bound.Step(*f.model, Load(3.0), true, f.x, f.sd, 200.0, 1.0, 2.0, 2.0);
  ASSERT_EQ(f.bound.bound_degC().size(), 1);
  EXPECT_NEAR(f.bound.bound_degC()(0), Closed(30.0, 20.0, 18.0, 199.0), 1e-6);
}

TEST(SilenceBound, ARestartIsASilenceFromTheSavedState) {
  SilenceFixture f;
  // Saved 100 s before 0 s, at 30 degC; aged to 26 degC at the restart.
  f.bound.Begin(Eigen::VectorXd::Constant(1, 30.0), Load(1.0), -100.0,
                Eigen::VectorXd::Constant(1, 26.0), 0.0);
  f.x(0) = 25.0;
  f.Step(3.0, true);  // the first step with inputs after the restart ends at 1 s
  ASSERT_EQ(f.bound.bound_degC().size(), 1);
  EXPECT_NEAR(f.bound.bound_degC()(0), Closed(30.0, 20.0, 18.0, 101.0), 1e-6);
}

// While silent, with the largest current known: the one node at 5 A (50 W) from the estimate
// after the last step with inputs, the first-order response T(t) = Ta + P R + (T0 - Ta - P R)
// e^(-t / RC) (one_node_model.hpp), the published band on it at once (after min_silence_s), the
// levels on it as it was delay_s earlier.
TEST(SilenceBound, WhileSilentTheWorstCaseIsTheFirstOrderResponseAtTheLargestCurrent) {
  SilenceFixture f;
  f.bound = SilenceBound(SilenceWorstLoad{5.0, 0.0}, 10.0);
  f.Step(1.0, true);  // ends at 1 s, estimate 30 degC at 1 A: the silence starts here
  for (int k = 1; k <= 60; ++k) {
    f.x(0) = 30.0 - 0.01 * k;  // the estimate runs on at the held 1 A (its value plays no part)
    f.Step(1.0, false);
    const double worst = Closed(30.0, 20.0, 50.0, k), then = Closed(30.0, 20.0, 50.0, k - 10);
    if (k <= 2) {  // not yet longer than min_silence_s: no silence
      EXPECT_EQ(f.bound.worst_degC().size(), 0) << k;
    } else {
      ASSERT_EQ(f.bound.worst_degC().size(), 1) << k;
      EXPECT_NEAR(f.bound.worst_degC()(0), worst, 1e-9) << k;
    }
    if (k <= 10) {
      EXPECT_EQ(f.bound.delayed_worst_degC().size(), 0) << k;
    } else {
      ASSERT_EQ(f.bound.delayed_worst_degC().size(), 1) << k;
      EXPECT_NEAR(f.bound.delayed_worst_degC()(0), then, 1e-9) << k;
    }
  }
  EXPECT_NEAR(f.bound.worst_degC()(0), 48.05, 0.01);  // by hand: 70 - 40 e^-0.6
  f.Step(1.0, true);  // the frames are back: the worst case ends (the load is seen again)
  EXPECT_EQ(f.bound.worst_degC().size(), 0);
  EXPECT_EQ(f.bound.delayed_worst_degC().size(), 0);
  // A gap in a log runs as one step: the worst case is run over all of it.
  f.bound.Step(*f.model, Load(1.0), false, f.x, f.sd, f.t_s + 40.0, 1.0, 2.0, 2.0);
  ASSERT_EQ(f.bound.delayed_worst_degC().size(), 1);
  EXPECT_NEAR(f.bound.worst_degC()(0), Closed(f.x(0), 20.0, 50.0, 40.0), 1e-9);
  EXPECT_NEAR(f.bound.delayed_worst_degC()(0), Closed(f.x(0), 20.0, 50.0, 30.0), 1e-9);
}

TEST(SilenceBound, WithoutTheLargestCurrentOrAfterAResetNoWorstCase) {
  SilenceFixture f;  // max_current_A 0: not known
  f.Step(1.0, true);
  for (int k = 0; k < 30; ++k) f.Step(1.0, false);
  EXPECT_EQ(f.bound.worst_degC().size(), 0);
  EXPECT_EQ(f.bound.delayed_worst_degC().size(), 0);
  SilenceFixture g;
  g.bound = SilenceBound(SilenceWorstLoad{5.0, 0.0}, 0.0);
  g.Step(1.0, true);
  for (int k = 0; k < 5; ++k) g.Step(1.0, false);
  ASSERT_EQ(g.bound.delayed_worst_degC().size(), 1);  // delay 0: the levels on the worst case
  EXPECT_NEAR(g.bound.delayed_worst_degC()(0), Closed(30.0, 20.0, 50.0, 5.0), 1e-9);
  g.bound.Reset();  // the filter was reset: nothing to start a worst case from
  for (int k = 0; k < 5; ++k) g.Step(1.0, false);
  EXPECT_EQ(g.bound.worst_degC().size(), 0);
  EXPECT_THROW(SilenceBound(SilenceWorstLoad{5.0, 0.0}, -1.0), std::invalid_argument);
  EXPECT_THROW(SilenceBound(SilenceWorstLoad{-5.0, 0.0}, 1.0), std::invalid_argument);
}

TEST(SilenceBound, ARestartsWorstCaseStartsFromTheStateAgedToIt) {
  SilenceFixture f;
  f.bound = SilenceBound(SilenceWorstLoad{5.0, 0.0}, 0.0);
  f.bound.Begin(Eigen::VectorXd::Constant(1, 30.0), Load(1.0), -100.0,
                Eigen::VectorXd::Constant(1, 26.0), 0.0);
  for (int k = 1; k <= 5; ++k) f.Step(1.0, false);  // no frames yet after the restart
  ASSERT_EQ(f.bound.worst_degC().size(), 1);
  EXPECT_NEAR(f.bound.worst_degC()(0), Closed(26.0, 20.0, 50.0, 5.0), 1e-9);
}

// What the levels act on and what is published while silent: the levels on the worst case as it
// was silence_delay_s ago, the band x +- 2 sd reaching the worst case now.
TEST(AlarmValues, WhileSilentTheLevelsSeeTheDelayedWorstCaseTheBandTheWorstNow) {
  const ThermalModel model = ThermalModel::Parse(kOneNode, "one.toml");
  AlarmConfig config;
  config.silence_delay_s = 10.0;
  AlarmValues values(model, config, 0.0, 1.0, SilenceWorstLoad{5.0, 0.0});
  Eigen::VectorXd x = Eigen::VectorXd::Constant(1, 30.0), sd = Eigen::VectorXd::Constant(1, 0.5);
  const ThermalInputs in = Load(1.0);
  AlarmValuesStep s;
  s.period_s = 1.0;
  s.inputs = &in;
  s.x_degC = &x;
  s.sd_K = &sd;
  s.lagging_degC = kNoReading;
  for (int k = 0; k <= 30; ++k) {
    s.end_us = (k + 1) * 1'000'000;
    s.fresh_inputs = k == 0;  // silent after the first step
    values.Step(s);
  }
  const double then = Closed(30.0, 20.0, 50.0, 20.0), now = Closed(30.0, 20.0, 50.0, 30.0);
  EXPECT_NEAR(values.Value_degC(0, 30.0), then, 1e-9);
  EXPECT_EQ(values.ValueAndRule(0, 30.0).second, AlarmRule::kSilence);
  EXPECT_NEAR(values.BandTop_degC(0, values.Value_degC(0, 30.0)), now, 1e-9);
  EXPECT_NEAR(values.PublishedSd_K(0, 0.5, now - 30.0), (now - 30.0) / 2.0, 1e-12);
  s.end_us += 1'000'000;
  s.fresh_inputs = true;  // the frames are back at the same load: nothing above the estimate
  values.Step(s);
  EXPECT_EQ(values.Value_degC(0, 30.0), 30.0);
  EXPECT_EQ(values.ValueAndRule(0, 30.0).second, AlarmRule::kBand);
  EXPECT_EQ(values.BandTop_degC(0, values.Value_degC(0, 30.0)), 30.0);
}

// Running blind, the value is the worst case of an unseen cooling failure from the band's top
// when the measurements stopped, and the rule says so; an estimate above that worst case is the
// band rule's again.
TEST(AlarmValues, RunningBlindTheRuleIsBlindWhileItsWorstCaseIsTheHighest) {
  const ThermalModel model = ThermalModel::Parse(kOneNode, "one.toml");
  AlarmValues values(model, AlarmConfig{}, 0.0, 1.0);
  Eigen::VectorXd x = Eigen::VectorXd::Constant(1, 30.0), sd = Eigen::VectorXd::Constant(1, 0.5);
  const ThermalInputs in = Load(1.0);
  AlarmValuesStep s;
  s.period_s = 1.0;
  s.inputs = &in;
  s.fresh_inputs = true;
  s.x_degC = &x;
  s.sd_K = &sd;
  s.lagging_degC = kNoReading;
  for (int k = 0; k < 20; ++k) {
    s.end_us = (k + 1) * 1'000'000;
    s.blind = k >= 10;
    values.Step(s);
  }
  ASSERT_TRUE(values.Blind());
  const auto [value_degC, rule] = values.ValueAndRule(0, 30.0);
  EXPECT_GT(value_degC, 31.0);  // from 30 + 2 x 0.5, warming at 1 A without its cooling
  EXPECT_EQ(rule, AlarmRule::kBlind);
  EXPECT_EQ(values.ValueAndRule(0, value_degC + 1.0).second, AlarmRule::kBand);
  EXPECT_STREQ(AlarmRuleName(AlarmRule::kBlind), "blind");
}

TEST(WorstInputs, TheLargestCurrentOnTheQAxisAtTheLargestSpeed) {
  ThermalInputs held = Load(4.0);
  held.id_A = -3.0;
  held.speed_rpm = -1000.0;
  const ThermalInputs w = WorstInputs(held, SilenceWorstLoad{4.5, 21000.0});
  EXPECT_EQ(w.iq_A, 5.0);  // |i| held, 5 A, is above the largest current given: kept
  EXPECT_EQ(w.id_A, 0.0);
  EXPECT_EQ(w.speed_rpm, 21000.0);
  EXPECT_EQ(w.ambient_degC, 20.0);  // held
  const ThermalInputs v = WorstInputs(Load(1.0), SilenceWorstLoad{15.0, 0.0});
  EXPECT_EQ(v.iq_A, 15.0);
  EXPECT_EQ(v.speed_rpm, 0.0);
}

TEST(SilenceBound, AShortGapIsNoSilence) {
  SilenceFixture f;
  f.Step(1.0, true);
  f.Step(1.0, false);  // 1 s silent, not more than min_silence_s = 2 s
  f.Step(5.0, true);
  EXPECT_EQ(f.bound.bound_degC().size(), 0);
  f.Step(5.0, false);
  f.Step(5.0, false);
  f.Step(5.0, false);
  f.bound.Reset();
  f.Step(5.0, true);  // after a reset nothing is known of the silence's start
  EXPECT_EQ(f.bound.bound_degC().size(), 0);
}

TEST(WorseInputs, TakesTheLargerMagnitudes) {
  ThermalInputs a = Load(-4.0), b = Load(3.0);
  a.speed_rpm = 1000.0;
  b.speed_rpm = -2000.0;
  b.ambient_degC = 25.0;
  const ThermalInputs w = WorseInputs(a, b);
  EXPECT_EQ(w.iq_A, 4.0);
  EXPECT_EQ(w.speed_rpm, 2000.0);
  EXPECT_EQ(w.ambient_degC, 25.0);
}

// Blind, the one node loses its path to ambient: C dT/dt = P, 50 W into 100 J/K is 0.5 K/s from
// the estimate when the measurements stopped; Reset ends the bound.
TEST(BlindBound, TheNetworkWithoutItsBoundaryPathsFromTheLastEstimate) {
  const ThermalModel model = ThermalModel::Parse(kOneNode, "one.toml");
  BlindBound blind;
  EXPECT_EQ(blind.bound_degC().size(), 0);
  for (int k = 0; k < 10; ++k)
    blind.Step(model, Load(5.0), 1.0, Eigen::VectorXd::Constant(1, 50.0 + k));
  ASSERT_EQ(blind.bound_degC().size(), 1);
  EXPECT_NEAR(blind.bound_degC()(0), 55.0, 1e-9);  // from 50 (the first step's estimate), 10 s
  blind.Reset();
  EXPECT_EQ(blind.bound_degC().size(), 0);
}

// Two nodes in a chain, rotor - frame - ambient (R 2 and 1 K/W): 1 W on the rotor raises the
// frame by 1 K and the rotor by 1 + 2 K at steady state, 1 W on the frame raises both by 1 K, so
// K = G_rotor - G_frame is 2 K/W on the rotor and 0 on the frame.
constexpr const char* kRotorFrame = R"(
[model]
name = "two"
[[node]]
name = "frame"
capacity_J_per_K = 100
[[node]]
name = "rotor"
capacity_J_per_K = 50
[[edge]]
between = ["rotor", "frame"]
resistance_K_per_W = 2.0
[[edge]]
between = ["frame", "ambient"]
resistance_K_per_W = 1.0
[[loss]]
name = "joule"
power_W = "2.0 * iq_A^2"
shares = { frame = 1 }
)";

TEST(InsideHeatBound, GainsAreTheSteadyStateRiseOfTheRotorOverTheFrame) {
  const ThermalModel model = ThermalModel::Parse(kRotorFrame, "two");
  const int frame = model.StateIndex("frame"), rotor = model.StateIndex("rotor");
  const InsideHeatBound bound(model, frame, rotor, 1200.0, 10.0);
  ASSERT_EQ(bound.gain_K_per_W().size(), 2);
  EXPECT_NEAR(bound.gain_K_per_W()(rotor), 2.0, 1e-9);
  EXPECT_NEAR(bound.gain_K_per_W()(frame), 0.0, 1e-9);
  // No bound where the rotor is the measured node, or either is missing.
  EXPECT_EQ(InsideHeatBound(model, frame, frame, 1200.0, 10.0).gain_K_per_W().size(), 0);
  EXPECT_EQ(InsideHeatBound(model, -1, rotor, 1200.0, 10.0).gain_K_per_W().size(), 0);
  EXPECT_THROW(InsideHeatBound(model, frame, rotor, 0.0, 10.0), std::invalid_argument);
  EXPECT_THROW(InsideHeatBound(model, frame, rotor, 1200.0, 0.0), std::invalid_argument);
}

TEST(InsideHeatBound, PutsTheFramePathHeatFoundSinceTheOnsetOnTheRotorUntilAFramePathName) {
  const ThermalModel model = ThermalModel::Parse(kRotorFrame, "two");
  const int frame = model.StateIndex("frame"), rotor = model.StateIndex("rotor");
  InsideHeatBound bound(model, frame, rotor, 1200.0, 10.0);
  // 1 W of usual model error, 5 W from 300 s on; named inside at 400 s with its onset at 300 s.
  for (int t = 1; t < 400; ++t) {
    bound.Step(t, t <= 300 ? 1.0 : 5.0, InsideHeatVerdict::kUnchanged, kNoReading);
    EXPECT_EQ(bound.shift_K(rotor), 0.0) << t;
  }
  bound.Step(400.0, 5.0, InsideHeatVerdict::kInside, 300.0);
  EXPECT_TRUE(bound.latched());
  EXPECT_NEAR(bound.heat_W(), 4.0, 1e-12);
  EXPECT_NEAR(bound.shift_K(rotor), 8.0, 1e-9);
  EXPECT_NEAR(bound.shift_K(frame), 0.0, 1e-9);
  // Held once the test clears (the heat stays), following the frame-path heat.
  bound.Step(401.0, 7.0, InsideHeatVerdict::kUnchanged, kNoReading);
  EXPECT_NEAR(bound.heat_W(), 6.0, 1e-12);
  bound.Step(402.0, kNoReading, InsideHeatVerdict::kUnchanged, kNoReading);  // none this step: held
  EXPECT_NEAR(bound.heat_W(), 6.0, 1e-12);
  bound.Step(403.0, 0.5, InsideHeatVerdict::kUnchanged, kNoReading);  // below the base: none
  EXPECT_EQ(bound.heat_W(), 0.0);
  bound.Step(404.0, 7.0, InsideHeatVerdict::kFramePath, kNoReading);  // named on the frame path
  EXPECT_FALSE(bound.latched());
  EXPECT_EQ(bound.shift_K(rotor), 0.0);
  bound.Step(405.0, 7.0, InsideHeatVerdict::kInside, kNoReading);  // no onset: the oldest kept, 1 W
  EXPECT_NEAR(bound.heat_W(), 6.0, 1e-12);
  bound.Reset();
  EXPECT_FALSE(bound.latched());
  EXPECT_EQ(bound.heat_W(), 0.0);
}

}  // namespace
}  // namespace pumptherm::estimators
