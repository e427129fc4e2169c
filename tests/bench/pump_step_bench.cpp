// One thermal period of a pump as the daemon runs it (daemon::Pump: 1, 10 or 100 paired fast
// samples and a status frame, then Advance over the period: the identifier's sample, the pump
// estimator's step with its readings, the mismatch test, the bounds, the forecast and the alarms),
// on tmp-generic with the demo's settings (disturbance states, a 30 s sensor lag, the magnet from
// the flux on the rotor, winding levels 100/120 degC). Counts heap allocations by interposing
// malloc and reports them per step (`allocs_per_step`); goal: 0.
#include <benchmark/benchmark.h>

#include <atomic>
#include <cmath>
#include <cstdlib>
#include <memory>

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
/// apart), then Advance to it. uq is the shipped motor's at 40 degC of winding and magnet.
void Period(pd::Pump& pump, std::int64_t t_us, double iq_A, double frame_degC, int samples) {
  static const pe::MotorDescription motor = pe::MotorPreset("han2019-tmp");
  static const pe::VoltageLaw law = pe::VoltageLawOf(motor);
  const double w = pe::ElectricalSpeed_rad_per_s(motor, 21000.0);
  pe::QAxisState at40;
  at40.winding_degC = at40.magnet_degC = 40.0;
  const double uq_V =
      pe::QAxisVoltage_V(law, {iq_A, w}, at40) + pe::QAxisKnownTerms_V(motor, 0.0, iq_A, w);
  for (int k = samples; k > 0; --k) {
    const std::int64_t t = t_us - 20'000 - 10'000 * static_cast<std::int64_t>(k - 1);
    pump.OnCurrents(t, 0.0, iq_A, w, 3.0);
    pump.OnVoltages(t + 1'000, -0.01, uq_V, 3.0);
  }
  pump.OnStatus(t_us - 10'000, 21000.0, 2.0, frame_degC, 22.0);
  benchmark::DoNotOptimize(pump.Advance(t_us));
}

void BM_PumpPeriod(benchmark::State& state) {
  pd::PumpConfig c;
  c.name = "bench";
  c.magnet_node = "rotor";
  c.frame_sensor_lag_s = 30.0;
  c.disturbance_states = true;
  c.disturbance_states_explicit = true;
  c.alarms.levels["winding"].limits = {100.0, 120.0};
  const auto model = TmpGeneric();
  pd::Pump pump(c, pe::MotorPreset("han2019-tmp"), model, 1.0);
  const int samples = static_cast<int>(state.range(0));
  std::int64_t t_us = 1'000'000;
  // Warm up over a load step: workspaces sized, the mismatch test past its learning.
  for (int k = 0; k < 1200; ++k, t_us += 1'000'000)
    Period(pump, t_us, k < 600 ? 2.0 : 3.0, 30.0 + 0.001 * k, samples);
  const long before = g_allocations.load();
  long steps = 0;
  for (auto _ : state) {
    Period(pump, t_us, 3.0, 31.2 + 0.1 * static_cast<double>(steps & 1), samples);
    t_us += 1'000'000;
    ++steps;
  }
  state.counters["allocs_per_step"] =
      static_cast<double>(g_allocations.load() - before) / static_cast<double>(steps);
  state.counters["voltage_fused"] =
      pump.snapshot().voltage_reading.state == pe::ReadingState::kFused ? 1.0 : 0.0;
}
// 1 sample a period: too few for the voltage reading (stale); 10: its least, fused; 100: the
// drives' 100 Hz.
BENCHMARK(BM_PumpPeriod)->Arg(1)->Arg(10)->Arg(100);

}  // namespace

BENCHMARK_MAIN();
