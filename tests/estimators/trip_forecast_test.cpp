#include "estimators/trip_forecast.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "tests/estimators/one_node_model.hpp"

namespace pumptherm::estimators {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

using test::kOneNode;

ThermalInputs At5A() {
  ThermalInputs in;
  in.iq_A = 5.0;  // 50 W: steady state 70 degC at 20 degC ambient
  in.ambient_degC = in.coolant_degC = 20.0;
  return in;
}

TEST(TripForecast, TimeToALevelOnTheWayToTheSteadyStateIsTheClosedForm) {
  const ThermalModel model = ThermalModel::Parse(kOneNode, "one.toml");
  TripForecast forecast(1);
  int node = -2;
  // 70 - 50 e^(-t/100) = 60: t = 100 ln 5 = 160.9 s; linear inside a 10 s step of a slowing rise.
  const double t = forecast.TimeToTrip_s(model, At5A(), Eigen::VectorXd::Constant(1, 20.0), {60.0},
                                         nullptr, &node);
  EXPECT_NEAR(t, 100.0 * std::log(5.0), 1.0);
  EXPECT_EQ(node, 0);
}

TEST(TripForecast, NoTripAboveTheSteadyStateNoneWithoutLevelsAndZeroWhenThere) {
  const ThermalModel model = ThermalModel::Parse(kOneNode, "one.toml");
  TripForecast forecast(1);
  int node = -2;
  EXPECT_EQ(forecast.TimeToTrip_s(model, At5A(), Eigen::VectorXd::Constant(1, 20.0), {80.0},
                                  nullptr, &node),
            kInf);
  EXPECT_EQ(node, -1);
  EXPECT_EQ(forecast.TimeToTrip_s(model, At5A(), Eigen::VectorXd::Constant(1, 20.0), {kInf},
                                  nullptr, &node),
            kInf);
  EXPECT_EQ(forecast.TimeToTrip_s(model, At5A(), Eigen::VectorXd::Constant(1, 65.0), {60.0},
                                  nullptr, &node),
            0.0);
  EXPECT_EQ(node, 0);
}

}  // namespace
}  // namespace pumptherm::estimators
