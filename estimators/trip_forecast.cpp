#include "estimators/trip_forecast.hpp"

#include <algorithm>
#include <cmath>
#include <exception>
#include <limits>

namespace pumptherm::estimators {

namespace {
constexpr double kInf = std::numeric_limits<double>::infinity();

/// steady = -A^-1 f (A x + f = 0) on a fixed size N: the LU of a dynamic-size 4 x 4 spends most
/// of its instructions on its set-up. Up to 4 x 4 Eigen inverts in closed form (cofactors), in
/// fewer instructions than the fixed-size LU; A (conductances over capacities, the network tied
/// to its boundaries) is far from singular, and a singular A still gives non-finite values.
template <int N>
void SteadyStateFixed(const Eigen::MatrixXd& a, const Eigen::VectorXd& f, Eigen::VectorXd& steady) {
  using M = Eigen::Matrix<double, N, N>;
  using V = Eigen::Matrix<double, N, 1>;
  if constexpr (N <= 4) {
    Eigen::Map<V>(steady.data()).noalias() =
        -(Eigen::Map<const M>(a.data()).inverse() * Eigen::Map<const V>(f.data()));
  } else {
    const Eigen::PartialPivLU<M> lu(Eigen::Map<const M>(a.data()));
    Eigen::Map<V>(steady.data()) = -lu.solve(Eigen::Map<const V>(f.data()));
  }
}
}  // namespace

TripForecast::TripForecast(int states) : x_(states), next_(states), steady_(states) {}

double TripForecast::TimeToTrip_s(const ThermalModel& model, const ThermalInputs& in,
                                  const Eigen::VectorXd& x_degC,
                                  const std::vector<double>& trip_degC,
                                  const ThermalObserver* observer, int* node) {
  *node = -1;
  const auto n = static_cast<std::size_t>(x_degC.size());
  if (trip_degC.size() < n ||
      std::none_of(trip_degC.begin(), trip_degC.end(), [](double t) { return std::isfinite(t); })) {
    return kInf;
  }
  x_ = x_degC;
  for (std::size_t i = 0; i < n; ++i) {
    if (x_(static_cast<Eigen::Index>(i)) >= trip_degC[i]) {
      *node = static_cast<int>(i);
      return 0.0;
    }
  }
  try {
    // The steady state at these inputs, A x + f = 0 (ThermalModel::SteadyState_degC), into
    // members: no allocation per call. A singular A gives non-finite values: no forecast.
    model.Linearise(in, lin_);
    if (observer) observer->AddFoundHeat(lin_);
    const auto rows = lin_.a_per_s.rows();
    const bool sized = steady_.size() == rows && lin_.f_K_per_s.size() == rows;
    if (sized && rows == 4) {  // tmp-generic's nodes
      SteadyStateFixed<4>(lin_.a_per_s, lin_.f_K_per_s, steady_);
    } else if (sized && rows == 7) {  // saheba2010-*'s
      SteadyStateFixed<7>(lin_.a_per_s, lin_.f_K_per_s, steady_);
    } else {
      lu_.compute(lin_.a_per_s);
      steady_.noalias() = lu_.solve(lin_.f_K_per_s);
      steady_ = -steady_;
    }
    if (!steady_.allFinite()) return kInf;
    bool reaches = false;
    for (std::size_t i = 0; i < n; ++i)
      reaches = reaches || steady_(static_cast<Eigen::Index>(i)) >= trip_degC[i];
    if (!reaches) return kInf;
    model.Linearise(in, x_, lin_);
    if (observer) observer->AddFoundHeat(lin_);
    disc_.Update(lin_, kStep_s);
  } catch (const std::exception&) {
    return kInf;
  }
  for (double t = 0.0; t < kLimit_s; t += kStep_s) {
    disc_.Propagate(x_, lin_, next_);
    for (std::size_t i = 0; i < n; ++i) {
      const auto k = static_cast<Eigen::Index>(i);
      if (next_(k) >= trip_degC[i]) {
        *node = static_cast<int>(i);
        const double frac = (trip_degC[i] - x_(k)) / (next_(k) - x_(k));
        return t + kStep_s * std::clamp(frac, 0.0, 1.0);
      }
    }
    x_.swap(next_);
  }
  return kInf;
}

}  // namespace pumptherm::estimators
