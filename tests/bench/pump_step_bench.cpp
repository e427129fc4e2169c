// One thermal period of a pump as the daemon runs it (daemon::Pump: 1, 10 or 100 paired fast
// samples and a status frame, then Advance over the period: the identifier's sample, the pump
// estimator's step with its readings, the mismatch test, the bounds, the forecast and the alarms),
// on tmp-generic with the demo's settings (disturbance states, a 30 s sensor lag, the magnet from
// the flux on the rotor, winding levels 100/120 degC). Counts heap allocations by interposing
// malloc and reports them per step (`allocs_per_step`); goal: 0.
#include <benchmark/benchmark.h>

#include <Eigen/LU>
#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdlib>
#include <memory>
#include <string>

#include "daemon/config.hpp"
#include "daemon/pump.hpp"
#include "estimators/voltage_equation.hpp"
#include "tests/common/test_files.hpp"

namespace {
std::atomic<long> g_allocations{0};
}  // namespace

extern "C" void* __libc_malloc(std::size_t size);
extern "C" void* malloc(std::size_t size) {
  g_allocations.fetch_add(1, std::memory_order_relaxed);
  return __libc_malloc(size);
}

namespace pd = pumptherm::daemon;
namespace pe = pumptherm::estimators;

namespace {

std::shared_ptr<const pe::ThermalModel> TmpGeneric() {
  const std::string path = pumptherm::test_files::ModelPath("tmp-generic");
  return std::make_shared<const pe::ThermalModel>(
      pe::ThermalModel::Parse(pumptherm::test_files::ReadFile(path), "tmp-generic",
                              pe::ThermalModelFiles{pumptherm::test_files::DirectoryOf(path),
                                                    &pumptherm::test_files::ReadFile}));
}

/// One period's frames ending at `t_us` (`samples` paired current and voltage frames, 10 ms
/// apart), then Advance to it. uq is the shipped motor's at `at` (winding and magnet).
void Period(pd::Pump& pump, std::int64_t t_us, double iq_A, double frame_degC, int samples,
            const pe::QAxisState& at) {
  static const pe::MotorDescription motor = pe::MotorPreset("han2019-tmp");
  static const pe::VoltageLaw law = pe::VoltageLawOf(motor);
  const double w = pe::ElectricalSpeed_rad_per_s(motor, 21000.0);
  const double uq_V =
      pe::QAxisVoltage_V(law, {iq_A, w}, at) + pe::QAxisKnownTerms_V(motor, 0.0, iq_A, w);
  for (int k = samples; k > 0; --k) {
    const std::int64_t t = t_us - 20'000 - 10'000 * static_cast<std::int64_t>(k - 1);
    pump.OnCurrents(t, 0.0, iq_A, w, 3.0);
    pump.OnVoltages(t + 1'000, -0.01, uq_V, 3.0);
  }
  pump.OnStatus(t_us - 10'000, 21000.0, 2.0, frame_degC, 22.0);
  benchmark::DoNotOptimize(pump.Advance(t_us));
}

pe::QAxisState At(double winding_degC, double magnet_degC) {
  pe::QAxisState at;
  at.winding_degC = winding_degC;
  at.magnet_degC = magnet_degC;
  return at;
}

pd::PumpConfig BenchConfig() {
  pd::PumpConfig c;
  c.name = "bench";
  c.magnet_node = "rotor";
  c.frame_sensor_lag_s = 30.0;
  c.disturbance_states = true;
  c.disturbance_states_explicit = true;
  c.alarms.levels["winding"].limits = {100.0, 120.0};
  return c;
}

/// Counters every benchmark reports: heap allocations per timed step (goal 0), whether the
/// voltage was fused in the last step, and whether the mismatch test failed then (its naming
/// fit runs every refit period while it does).
void Report(benchmark::State& state, const pd::Pump& pump, long allocations, long steps) {
  state.counters["allocs_per_step"] =
      static_cast<double>(allocations) / static_cast<double>(std::max(steps, 1L));
  state.counters["voltage_fused"] =
      pump.snapshot().voltage_reading.state == pe::ReadingState::kFused ? 1.0 : 0.0;
  const pe::MismatchState m = pump.snapshot().mismatch.state;
  state.counters["mismatch_failing"] =
      m == pe::MismatchState::kConsistent || m == pe::MismatchState::kLearning ? 0.0 : 1.0;
}

/// The model's steady state at `in`: a x + f = 0, linearised again at the solution (the copper
/// loss grows with the winding's temperature) until it settles.
Eigen::VectorXd SteadyState_degC(const pe::ThermalModel& model, const pe::ThermalInputs& in) {
  Eigen::VectorXd x = Eigen::VectorXd::Constant(model.StateCount(), in.ambient_degC);
  pe::ThermalLinearModel lin;
  for (int k = 0; k < 8; ++k) {
    model.Linearise(in, x, lin);
    x = lin.a_per_s.partialPivLu().solve(-lin.f_K_per_s);
  }
  return x;
}

int NodeIndex(const pe::ThermalModel& model, const std::string& name) {
  const auto& names = model.StateNames();
  return static_cast<int>(std::find(names.begin(), names.end(), name) - names.begin());
}

/// A pump whose telemetry the model does not explain (uq of a winding and magnet held at 40 degC
/// while the frame warms): the mismatch test fails, and its naming fit runs once a minute.
void BM_PumpPeriod(benchmark::State& state) {
  const auto model = TmpGeneric();
  pd::Pump pump(BenchConfig(), pe::MotorPreset("han2019-tmp"), model, 1.0);
  const int samples = static_cast<int>(state.range(0));
  std::int64_t t_us = 1'000'000;
  // Warm up over a load step: workspaces sized, the mismatch test past its learning.
  for (int k = 0; k < 1200; ++k, t_us += 1'000'000)
    Period(pump, t_us, k < 600 ? 2.0 : 3.0, 30.0 + 0.001 * k, samples, At(40.0, 40.0));
  const long before = g_allocations.load();
  long steps = 0;
  for (auto _ : state) {
    Period(pump, t_us, 3.0, 31.2 + 0.1 * static_cast<double>(steps & 1), samples, At(40.0, 40.0));
    t_us += 1'000'000;
    ++steps;
  }
  Report(state, pump, g_allocations.load() - before, steps);
}

/// A healthy pump at a steady load: the frame reading (12-bit, 0.1 K steps) and uq at the
/// model's own steady state, so the mismatch test passes and no naming fit runs. The pump's
/// ordinary step. The current alternates by one 10 mA step, as a drive's reading does, so that
/// no two periods have the same inputs.
void BM_PumpPeriodSteady(benchmark::State& state) {
  const auto model = TmpGeneric();
  pd::Pump pump(BenchConfig(), pe::MotorPreset("han2019-tmp"), model, 1.0);
  const int samples = static_cast<int>(state.range(0));
  pe::ThermalInputs in;
  in.speed_rpm = 21000.0;
  in.iq_A = 3.0;
  in.ambient_degC = 22.0;
  const Eigen::VectorXd x = SteadyState_degC(*model, in);
  const double frame_degC = std::round(10.0 * x(NodeIndex(*model, "frame"))) / 10.0;
  const pe::QAxisState at = At(x(NodeIndex(*model, "winding")), x(NodeIndex(*model, "rotor")));
  std::int64_t t_us = 1'000'000;
  // Warm up at the steady state: the filter settled, the mismatch test past its learning.
  auto step = [&](long k) {
    const double odd = static_cast<double>(k & 1);
    Period(pump, t_us, 3.0 + 0.01 * odd, frame_degC + 0.1 * odd, samples, at);
    t_us += 1'000'000;
  };
  for (long k = 0; k < 1800; ++k) step(k);
  const long before = g_allocations.load();
  long steps = 0;
  for (auto _ : state) step(steps++);
  Report(state, pump, g_allocations.load() - before, steps);
}
BENCHMARK(BM_PumpPeriod)->Arg(1)->Arg(10)->Arg(100);
BENCHMARK(BM_PumpPeriodSteady)->Arg(10)->Arg(100);

}  // namespace

BENCHMARK_MAIN();
