// One step of the virtual thermal sensor on the 7-state Saheba network (issue 5 goal: <= 2 us,
// no allocation). Counts heap allocations by replacing the global operator new in this
// executable and reports them per step as the counter `allocs_per_step`.
#include <benchmark/benchmark.h>

#include <atomic>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <new>
#include <sstream>
#include <string>

#include "estimators/kalman_virtual_sensor.hpp"

namespace {
std::atomic<long> g_allocations{0};
}  // namespace

// GCC 12 pairs the replaced operator new below with std::free across inlining and warns
// (-Wmismatched-new-delete); new and delete here are a matched malloc/free pair.
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"

void* operator new(std::size_t size) {
  g_allocations.fetch_add(1, std::memory_order_relaxed);
  if (void* p = std::malloc(size == 0 ? 1 : size)) return p;
  throw std::bad_alloc();
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }

namespace pe = pumptherm::estimators;

namespace {

pe::ThermalModel Load(const std::string& name) {
  std::ifstream f(std::string(PUMPTHERM_SOURCE_DIR) + "/estimators/models/" + name + ".toml");
  std::stringstream ss;
  ss << f.rdbuf();
  return pe::ThermalModel::Parse(ss.str(), name);
}

/// Linearise (losses with the copper law), discretisation check, time and measurement update:
/// everything the daemon does once per period, at a steady operating point.
void BM_VirtualSensorStep(benchmark::State& state) {
  const auto model = Load("saheba2010-improved");
  pe::VirtualSensorConfig cfg;
  const bool fuse = state.range(0) != 0;
  pe::VirtualThermalSensor vts(model, cfg);
  vts.Initialise(Eigen::VectorXd::Constant(7, 30.0));
  pe::ThermalInputs in;
  in.speed_rpm = 800.0;
  in.iq_A = 50.0;
  in.ambient_degC = 22.0;
  Eigen::VectorXd y = Eigen::VectorXd::Constant(1, 30.0);
  const double w = fuse ? 40.0 : std::nan("");
  for (int k = 0; k < 100; ++k) vts.Step(in, 1.0, y, w);  // warm up: workspaces sized
  const long before = g_allocations.load();
  long steps = 0;
  for (auto _ : state) {
    y(0) = 30.0 + 1e-3 * static_cast<double>(steps & 7);
    benchmark::DoNotOptimize(vts.Step(in, 1.0, y, w).nis);
    ++steps;
  }
  state.counters["allocs_per_step"] =
      static_cast<double>(g_allocations.load() - before) / static_cast<double>(steps);
  state.counters["rediscretisations"] = static_cast<double>(vts.Discretiser().Recomputations());
}
BENCHMARK(BM_VirtualSensorStep)->Arg(0)->Arg(1)->ArgName("fuse_winding");

/// The filter alone (time + Joseph measurement update), 7 states, 1 measurement.
void BM_KalmanPredictUpdate7(benchmark::State& state) {
  pe::KalmanFilter kf(7);
  kf.Reset(Eigen::VectorXd::Zero(7), Eigen::MatrixXd::Identity(7, 7));
  const Eigen::MatrixXd a = Eigen::MatrixXd::Identity(7, 7) * 0.99;
  const Eigen::VectorXd u = Eigen::VectorXd::Zero(7);
  const Eigen::MatrixXd q = Eigen::MatrixXd::Identity(7, 7) * 0.008;
  Eigen::MatrixXd c = Eigen::MatrixXd::Zero(1, 7);
  c(0, 0) = 1.0;
  const Eigen::VectorXd y = Eigen::VectorXd::Ones(1);
  const Eigen::MatrixXd r = Eigen::MatrixXd::Constant(1, 1, 0.003);
  kf.Predict(a, u, q);
  kf.Update(c, y, r);
  const long before = g_allocations.load();
  long steps = 0;
  for (auto _ : state) {
    kf.Predict(a, u, q);
    benchmark::DoNotOptimize(kf.Update(c, y, r).nis);
    ++steps;
  }
  state.counters["allocs_per_step"] =
      static_cast<double>(g_allocations.load() - before) / static_cast<double>(steps);
}
BENCHMARK(BM_KalmanPredictUpdate7);

/// A new exact discretisation (augmented 14 x 14 matrix exponential): the cost paid when the
/// operating point moves beyond the tolerance.
void BM_Rediscretise7(benchmark::State& state) {
  const auto model = Load("saheba2010-improved");
  pe::ThermalInputs in;
  in.speed_rpm = 800.0;
  in.iq_A = 50.0;
  pe::ThermalLinearModel lin;
  model.Linearise(in, lin);
  pe::ThermalDiscreteModel d;
  for (auto _ : state) {
    pe::DiscretiseZoh(lin.a_per_s, 1.0, d);
    benchmark::DoNotOptimize(d.ad(0, 0));
  }
}
BENCHMARK(BM_Rediscretise7);

/// `--fixed-steps N`: N steps of the virtual sensor and nothing else, for an instruction count
/// that does not depend on the machine's load:
///   valgrind --tool=callgrind thermal_filter_bench --fixed-steps 0      (set-up only)
///   valgrind --tool=callgrind thermal_filter_bench --fixed-steps 2000
/// (difference / 2000 = instructions per step).
int FixedSteps(long steps) {
  const auto model = Load("saheba2010-improved");
  pe::VirtualThermalSensor vts(model, {});
  vts.Initialise(Eigen::VectorXd::Constant(7, 30.0));
  pe::ThermalInputs in;
  in.speed_rpm = 800.0;
  in.iq_A = 50.0;
  in.ambient_degC = 22.0;
  Eigen::VectorXd y = Eigen::VectorXd::Constant(1, 30.0);
  for (int k = 0; k < 100; ++k) vts.Step(in, 1.0, y, std::nan(""));
  double nis = 0.0;
  for (long k = 0; k < steps; ++k) {
    y(0) = 30.0 + 1e-3 * static_cast<double>(k & 7);
    nis += vts.Step(in, 1.0, y, std::nan("")).nis;
  }
  return nis > 1e300 ? 1 : 0;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc == 3 && std::string(argv[1]) == "--fixed-steps") return FixedSteps(std::atol(argv[2]));
  benchmark::Initialize(&argc, argv);
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
