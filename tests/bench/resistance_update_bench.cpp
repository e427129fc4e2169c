// Cost of one update of each resistance identifier (target: a DFRLS update <= 50 ns on
// one core). Prints figures; never fails on time.
//   build-*/tests/bench/resistance_update_bench
#include <benchmark/benchmark.h>

#include <cmath>
#include <random>
#include <vector>

#include "estimators/motor.hpp"
#include "estimators/resistance_identifier.hpp"
#include "estimators/resistance_rls.hpp"

namespace est = pumptherm::estimators;

namespace {

// 4096 noisy samples of the Han 2019 motor at rated speed with load changes, reused cyclically.
struct Data {
  std::vector<Eigen::Vector2d> phi;
  std::vector<double> y;
  std::vector<est::DqSample> dq;
  Data() {
    std::mt19937_64 rng(1);
    std::normal_distribution<double> n(0.0, 1.0);
    for (int k = 0; k < 4096; ++k) {
      const double iq = 1.0 + 3.0 * std::abs(std::sin(0.01 * (k / 512))) + 0.01 * n(rng);
      const double w = 2199.1 + 0.1 * n(rng);
      const double uq = 0.28 * iq + 0.0182 * w + 0.01 * n(rng);
      phi.emplace_back(iq, w);
      y.push_back(uq);
      dq.push_back({0.0, iq, -0.24e-3 * w * iq, uq, w});
    }
  }
};
const Data& TheData() {
  static const Data d;
  return d;
}

void RunRls(benchmark::State& state, const est::RlsConfig& config) {
  const Data& d = TheData();
  est::DiscountedRls rls(config, Eigen::Vector2d(0.28, 0.0182), 1.0);
  std::size_t k = 0;
  for (auto _ : state) {
    benchmark::DoNotOptimize(rls.Update(d.phi[k], d.y[k]));
    k = (k + 1) & 4095;
  }
  benchmark::DoNotOptimize(rls.theta());
}

void BM_DfrlsUpdate(benchmark::State& s) { RunRls(s, est::RlsConfig::Dfrls()); }
void BM_RlsForgettingUpdate(benchmark::State& s) { RunRls(s, est::RlsConfig::Forgetting()); }
void BM_RlsUpdate(benchmark::State& s) { RunRls(s, est::RlsConfig::Plain()); }

// The project's identifier per raw sample (one block update every `block` samples).
void BM_IdentifierUpdate(benchmark::State& state) {
  const Data& d = TheData();
  est::ResistanceIdentifierConfig config;
  config.block_samples = static_cast<int>(state.range(0));
  est::ResistanceIdentifier id(est::MotorPreset("han2019-tmp"), config);
  std::size_t k = 0;
  for (auto _ : state) {
    benchmark::DoNotOptimize(id.Update(d.dq[k], 0.01));
    k = (k + 1) & 4095;
  }
}

}  // namespace

BENCHMARK(BM_DfrlsUpdate);
BENCHMARK(BM_RlsForgettingUpdate);
BENCHMARK(BM_RlsUpdate);
BENCHMARK(BM_IdentifierUpdate)->Arg(100)->Arg(1);
