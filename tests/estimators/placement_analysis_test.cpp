// Sensor placement (Saheba 2010 eqs. 35-37).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <fstream>
#include <sstream>

#include "estimators/placement.hpp"
#include "tests/common/test_files.hpp"

namespace pe = pumptherm::estimators;

TEST(Placement, RiccatiMeanMatchesLocalLevelClosedForm) {
  // For the local level model (A_D = 1, C = 1) the posterior variance tends to
  // P r / (P + r) with P = (q + sqrt(q^2 + 4 q r)) / 2 (Durbin and Koopman 2012, section 2.11);
  // starting there, every term of eq. 36 equals it.
  const double q = 0.5, r = 0.2;
  const double p = (q + std::sqrt(q * q + 4 * q * r)) / 2.0;
  const double post = p * r / (p + r);
  const Eigen::MatrixXd one = Eigen::MatrixXd::Identity(1, 1);
  const double mse = pe::MeanPosteriorTrace({one}, 100, one, q * one, r * one, post * one, one);
  EXPECT_NEAR(mse, post, 1e-12);
}

TEST(Placement, SahebaImprovedRanksTheWindingSensorsBestForTheWindings) {
  const auto m =
      pe::ThermalModel::Parse(pumptherm::test_files::ReadModel("saheba2010-improved"), "improved");
  pe::PlacementConfig cfg;
  for (double i : {40.0, 52.5, 65.0}) {
    pe::ThermalInputs in;
    in.speed_rpm = 800.0;
    in.iq_A = i;
    cfg.operating_points.push_back(in);
  }
  cfg.steps = 600;
  const auto rows = pe::SensorPlacement(m, cfg);
  ASSERT_EQ(rows.size(), 7u);
  // Table 6: the slot or end winding sensor gives the smallest winding MSE; the frame the largest
  // of the five stator candidates.
  EXPECT_LT(rows[3].mse_windings, rows[0].mse_windings);
  EXPECT_LT(rows[4].mse_windings, rows[0].mse_windings);
  EXPECT_LT(rows[3].mse_windings, rows[1].mse_windings);
  for (const auto& r : rows) EXPECT_GT(r.mse_all, r.mse_windings) << r.node;
}
