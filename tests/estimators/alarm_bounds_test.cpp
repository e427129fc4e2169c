#include "estimators/alarm_bounds.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <stdexcept>

#include "tests/estimators/one_node_model.hpp"

namespace pumptherm::estimators {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

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
  EXPECT_EQ(bias.Step(57.0), 0.0);   // against 60: cooling, the safe side
  EXPECT_EQ(bias.Step(kNaN), 0.0);   // no reading
  EXPECT_EQ(bias.Step(70.0), 12.0);  // against 58
  EXPECT_EQ(bias.Step(72.0), 15.0);  // against 57
  EXPECT_EQ(bias.Step(73.0), 0.0);   // against the missing reading
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
  f.bound.Begin(Eigen::VectorXd::Constant(1, 30.0), Load(1.0), -100.0);  // saved 100 s before 0 s
  f.x(0) = 25.0;
  f.Step(3.0, true);  // the first step with inputs after the restart ends at 1 s
  ASSERT_EQ(f.bound.bound_degC().size(), 1);
  EXPECT_NEAR(f.bound.bound_degC()(0), Closed(30.0, 20.0, 18.0, 101.0), 1e-6);
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

}  // namespace
}  // namespace pumptherm::estimators
