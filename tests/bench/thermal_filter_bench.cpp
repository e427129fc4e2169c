// One step of the virtual thermal sensor on the 7-state Saheba network (goal: <= 2 us,
// no allocation), and on the 4-state Wallscheid network with its loss map and expressions.
// Counts heap allocations by interposing malloc in this executable and reports them
// per step as the counter `allocs_per_step`.
#include <benchmark/benchmark.h>

#include <atomic>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <memory>
#include <new>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "estimators/disturbance_sensor.hpp"
#include "estimators/kalman_virtual_sensor.hpp"
#include "estimators/mismatch_detector.hpp"
#include "tests/common/test_files.hpp"

namespace {
std::atomic<long> g_allocations{0};
}  // namespace

// Eigen allocates its dynamic matrices with std::malloc, not operator new, so counting operator
// new alone would miss them: malloc itself is interposed (glibc lets an executable define it;
// __libc_malloc is the real one). operator new goes through malloc and is counted too.
extern "C" void* __libc_malloc(std::size_t size);
extern "C" void* malloc(std::size_t size) {
  g_allocations.fetch_add(1, std::memory_order_relaxed);
  return __libc_malloc(size);
}

namespace pe = pumptherm::estimators;

namespace {

using pumptherm::test_files::ReadFile;

/// A model by name (shipped, or kept with the tests); the tables it names are read relative to it.
pe::ThermalModel Load(const std::string& name) {
  const std::string path = pumptherm::test_files::ModelPath(name);
  return pe::ThermalModel::Parse(
      ReadFile(path), name,
      pe::ThermalModelFiles{pumptherm::test_files::DirectoryOf(path), &ReadFile});
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

/// One step of the mismatch detector on tmp-generic (4 nodes, the sensor's lag and offset: 6
/// states) at a steady operating point with the test passing: what the daemon adds per period
/// and pump. The naming fit runs only when the test fails (BM_MismatchFit).
void BM_MismatchStep(benchmark::State& state) {
  const auto model = Load("tmp-generic");
  pe::MismatchDetectorConfig c;
  c.sensor_lag_s = 30.0;
  pe::MismatchDetector det(model, c);
  det.Initialise(30.0, 0.0);
  pe::ThermalInputs in;
  in.speed_rpm = 21000.0;
  in.iq_A = 2.0;
  in.ambient_degC = 22.0;
  double t = 0.0;
  for (int k = 0; k < 2000; ++k) det.Step(in, 1.0, 30.0, t += 1.0);  // warm up: sized, settled
  const long before = g_allocations.load();
  long steps = 0;
  for (auto _ : state) {
    benchmark::DoNotOptimize(
        det.Step(in, 1.0, 30.0 + 1e-3 * static_cast<double>(steps & 7), t += 1.0).window_nis);
    ++steps;
  }
  state.counters["allocs_per_step"] =
      static_cast<double>(g_allocations.load() - before) / static_cast<double>(steps);
}
BENCHMARK(BM_MismatchStep);

/// One step of the disturbance-state filter on tmp-generic (4 nodes, lag, frame-path heat,
/// rotor heat, loss scale, offset: 9 states; two Linearise calls for the loss column) at a
/// steady operating point; with magnet:1 also the magnet reading on the rotor (its bias state: 10
/// states, a 2-row update).
void BM_DisturbanceStep(benchmark::State& state) {
  const auto model = Load("tmp-generic");
  pe::DisturbanceSensorConfig c;
  c.sensor_lag_s = 30.0;
  const bool magnet = state.range(0) != 0;
  if (magnet) c.magnet_node = "rotor";
  pe::DisturbanceThermalSensor f(model, c);
  f.Initialise(30.0);
  pe::ThermalInputs in;
  in.speed_rpm = 21000.0;
  in.iq_A = 2.0;
  in.ambient_degC = 22.0;
  pe::DisturbanceReadings r;
  r.frame_degC = 30.0;
  if (magnet) {
    r.magnet_degC = 40.0;
    r.magnet_sd_K = 0.5;
    r.magnet_winding_gain = -0.13;
  }
  for (int k = 0; k < 2000; ++k) f.Step(in, 1.0, r);
  const long before = g_allocations.load();
  long steps = 0;
  for (auto _ : state) {
    r.frame_degC = 30.0 + 1e-3 * static_cast<double>(steps & 7);
    benchmark::DoNotOptimize(f.Step(in, 1.0, r).update->nis);
    ++steps;
  }
  state.counters["allocs_per_step"] =
      static_cast<double>(g_allocations.load() - before) / static_cast<double>(steps);
}
BENCHMARK(BM_DisturbanceStep)->ArgName("magnet")->Arg(0)->Arg(1);

/// The naming fit once (20 minutes of history at 1 s, 5 effects, the onset grid): what one
/// failing test costs at detection and then once a minute.
void BM_MismatchFit(benchmark::State& state) {
  const auto model = Load("tmp-generic");
  pe::MismatchDetectorConfig c;
  c.sensor_lag_s = 30.0;
  c.settle_s = 0.0;
  c.name_after_s = 0.0;
  c.refit_period_s = 1e-9;  // refit at every failing step
  pe::MismatchDetector det(model, c);
  pe::ThermalInputs in;
  in.speed_rpm = 21000.0;
  in.iq_A = 2.0;
  in.ambient_degC = 22.0;
  double t = 0.0;
  det.Initialise(22.0, 0.0);
  for (int k = 0; k < 1300; ++k) det.Step(in, 1.0, 22.0 + 0.01 * (k % 5), t += 1.0);
  double y = 40.0;  // a reading far off the model: the test fails and the fit runs every step
  for (auto _ : state) {
    benchmark::DoNotOptimize(det.Step(in, 1.0, y, t += 1.0).likelihood_ratio);
    y += 0.01;
  }
}
BENCHMARK(BM_MismatchFit)->Unit(benchmark::kMillisecond);

/// One step of the virtual sensor on `wallscheid2017-4node` with its loss map: 7
/// quantities, 2 table lookups, 4 input-dependent resistances (so the network is re-assembled
/// every step), a loss that reads the winding temperature. range(0) = 0: a steady operating point
/// (the discretisation is kept); 1: the operating point moves every step through the rows of the
/// Paderborn profile 46 (re-discretised whenever a moves beyond the tolerance).
void BM_WallscheidStep(benchmark::State& state) {
  const std::string data =
      std::string(PUMPTHERM_SOURCE_DIR) + "/../shared/data/paderborn/profile46_every10th_dt5s.csv";
  std::vector<pe::ThermalInputs> rows;
  std::unique_ptr<pe::ThermalModel> model;
  try {
    model = std::make_unique<pe::ThermalModel>(Load("wallscheid2017-4node"));
    // time_s,u_q,coolant,stator_winding,u_d,stator_tooth,motor_speed,i_d,i_q,stator_yoke,ambient,...
    std::stringstream text(ReadFile(data));
    std::string line;
    std::getline(text, line);
    while (std::getline(text, line)) {
      std::vector<double> v;
      std::stringstream cells(line);
      std::string c;
      while (std::getline(cells, c, ',')) v.push_back(std::stod(c));
      pe::ThermalInputs in;
      in.coolant_degC = v.at(2);
      in.speed_rpm = v.at(6);
      in.id_A = v.at(7);
      in.iq_A = v.at(8);
      in.ambient_degC = v.at(10);
      rows.push_back(in);
    }
  } catch (const std::exception& e) {
    state.SkipWithError(
        (std::string("needs the Paderborn data and loss map: ") + e.what()).c_str());
    return;
  }
  const bool moving = state.range(0) != 0;
  pe::VirtualSensorConfig cfg;
  cfg.measured_nodes = {"stator_yoke"};
  pe::VirtualThermalSensor vts(*model, cfg);
  vts.Initialise(Eigen::VectorXd::Constant(4, 60.0));
  Eigen::VectorXd y = Eigen::VectorXd::Constant(1, 60.0);
  for (std::size_t k = 0; k < rows.size(); ++k) vts.Step(rows[k], 0.5, y, std::nan(""));  // warm up
  const long before = g_allocations.load();
  const long rediscretised_before = vts.Discretiser().Recomputations();
  long steps = 0;
  for (auto _ : state) {
    const pe::ThermalInputs& in =
        rows[moving ? static_cast<std::size_t>(steps) % rows.size() : 100];
    y(0) = 60.0 + 1e-3 * static_cast<double>(steps & 7);
    benchmark::DoNotOptimize(vts.Step(in, 0.5, y, std::nan("")).nis);
    ++steps;
  }
  state.counters["allocs_per_step"] =
      static_cast<double>(g_allocations.load() - before) / static_cast<double>(steps);
  state.counters["rediscretised_per_step"] =
      static_cast<double>(vts.Discretiser().Recomputations() - rediscretised_before) /
      static_cast<double>(steps);
}
BENCHMARK(BM_WallscheidStep)->Arg(0)->Arg(1)->ArgName("moving");

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
