// Exact ZOH discretisation (Saheba 2010 eqs. 20-21) against fine-step integration.
#include "estimators/thermal_discretisation.hpp"

#include <gtest/gtest.h>

#include <cstdlib>
#include <fstream>
#include <sstream>

#include "tests/common/test_files.hpp"

namespace pe = pumptherm::estimators;

namespace {
pe::ThermalModel Improved() {
  return pe::ThermalModel::Parse(pumptherm::test_files::ReadModel("saheba2010-improved"),
                                 "improved");
}
}  // namespace

TEST(ThermalDiscretisation, ExactStepMatchesFineRungeKutta) {
  const auto m = Improved();
  pe::ThermalInputs in;
  in.speed_rpm = 800.0;
  in.iq_A = 60.0;
  in.ambient_degC = 21.0;
  pe::ThermalLinearModel lin;
  m.Linearise(in, lin);
  Eigen::VectorXd x0(7);
  x0 << 30, 35, 40, 50, 52, 33, 31;
  const double dt_s = 30.0;
  pe::ThermalDiscreteModel d;
  pe::DiscretiseZoh(lin.a_per_s, dt_s, d);
  const Eigen::VectorXd exact = d.ad * x0 + d.phi_s * lin.f_K_per_s;
  // Classical RK4 with 1 ms steps (the fastest time constant of the network is ~0.1 s).
  Eigen::VectorXd x = x0;
  const double h = 1e-3;
  auto f = [&](const Eigen::VectorXd& v) -> Eigen::VectorXd {
    return lin.a_per_s * v + lin.f_K_per_s;
  };
  for (int k = 0; k < static_cast<int>(dt_s / h); ++k) {
    const Eigen::VectorXd k1 = f(x), k2 = f(x + 0.5 * h * k1), k3 = f(x + 0.5 * h * k2),
                          k4 = f(x + h * k3);
    x += h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4);
  }
  for (int i = 0; i < 7; ++i) EXPECT_NEAR(exact(i), x(i), 1e-8) << "state " << i;
  // The step moved the state noticeably, so the comparison means something.
  EXPECT_GT((exact - x0).cwiseAbs().maxCoeff(), 0.5);
}

TEST(ThermalDiscretisation, RecomputesOnlyWhenTheOperatingPointMoves) {
  const auto m = Improved();
  pe::ThermalDiscretiser disc(1e-3);
  pe::ThermalLinearModel lin;
  pe::ThermalInputs in;
  in.speed_rpm = 800.0;
  in.iq_A = 50.0;
  m.Linearise(in, lin);
  EXPECT_TRUE(disc.Update(lin, 1.0));
  EXPECT_FALSE(disc.Update(lin, 1.0));
  in.iq_A = 50.01;  // a tiny change in copper-loss sensitivity
  m.Linearise(in, lin);
  EXPECT_FALSE(disc.Update(lin, 1.0));
  EXPECT_TRUE(disc.Update(lin, 2.0));  // the period changed
  in.iq_A = 100.0;
  m.Linearise(in, lin);
  EXPECT_TRUE(disc.Update(lin, 2.0));
  EXPECT_EQ(disc.Recomputations(), 3);
}

TEST(ThermalDiscretisation, ScalarCaseHasTheClosedForm) {
  // dx/dt = -x/tau + f: A_D = exp(-dt/tau), Phi = tau (1 - exp(-dt/tau)).
  Eigen::MatrixXd a(1, 1);
  a << -1.0 / 50.0;
  pe::ThermalDiscreteModel d;
  pe::DiscretiseZoh(a, 7.0, d);
  EXPECT_NEAR(d.ad(0, 0), std::exp(-7.0 / 50.0), 1e-14);
  EXPECT_NEAR(d.phi_s(0, 0), 50.0 * (1.0 - std::exp(-7.0 / 50.0)), 1e-12);
  EXPECT_THROW(pe::DiscretiseZoh(a, 0.0, d), std::invalid_argument);
}
