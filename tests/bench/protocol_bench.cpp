// Protocol figures: decode rate of 8-byte frames with 4 to 8 signals, and the time to
// load Model3CAN.dbc. Prints figures; never fails on time.
//
//   build-rel/tests/bench/protocol_bench --benchmark_repetitions=5
//   --benchmark_report_aggregates_only=true
//
// items_per_second of the BM_Decode* benchmarks is frames decoded per second on one core.
#include <benchmark/benchmark.h>

#include <array>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>
#include <vector>

#include "protocol/codec.hpp"
#include "protocol/dbc.hpp"
#include "tests/common/test_files.hpp"

namespace {

using namespace pumptherm::protocol;

std::filesystem::path SourceDir() {
  const char* dir = std::getenv("PUMPTHERM_SOURCE_DIR");
  return dir != nullptr ? dir : PUMPTHERM_SOURCE_DIR_DEFAULT;
}

using pumptherm::test_files::ReadFile;

/// 256 random 8-byte payloads, so the decoder cannot be folded into a constant.
std::vector<std::array<std::uint8_t, 8>> Frames() {
  std::mt19937_64 rng(42);
  std::vector<std::array<std::uint8_t, 8>> frames(256);
  for (auto& f : frames) {
    for (auto& b : f) b = static_cast<std::uint8_t>(rng());
  }
  return frames;
}

void DecodeLoop(benchmark::State& state, const DbcMessage& message) {
  const MessageCodec codec(message);
  const auto frames = Frames();
  std::vector<double> values(codec.signal_count());
  std::size_t i = 0;
  for (auto _ : state) {
    const auto& f = frames[i++ & 255];
    benchmark::DoNotOptimize(codec.Decode(std::span<const std::uint8_t>(f.data(), 8), values));
    benchmark::ClobberMemory();
  }
  state.SetItemsProcessed(static_cast<std::int64_t>(state.iterations()));
  state.counters["signals"] = static_cast<double>(codec.signal_count());
}

const Dbc& PumpthermDbc() {
  static const Dbc dbc =
      ParseDbc(ReadFile(SourceDir() / "protocol" / "pumptherm.dbc"), "pumptherm.dbc");
  return dbc;
}

/// PUMP_FAST_I: 4 Intel signals (two signed 16-bit with "not available" values, 24-bit, 4-bit).
void BM_DecodePumpFastI_4signals(benchmark::State& state) {
  DecodeLoop(state, *PumpthermDbc().FindMessage("PUMP_FAST_I"));
}
BENCHMARK(BM_DecodePumpFastI_4signals);

/// PUMP_STATUS: 6 Intel signals of 3 to 16 bits at odd offsets.
void BM_DecodePumpStatus_6signals(benchmark::State& state) {
  DecodeLoop(state, *PumpthermDbc().FindMessage("PUMP_STATUS"));
}
BENCHMARK(BM_DecodePumpStatus_6signals);

/// 8 Motorola signals, signed and unsigned, 8 bytes.
void BM_DecodeMotorola_8signals(benchmark::State& state) {
  static const Dbc dbc = ParseDbc(
      "BO_ 1 M: 8 X\n"
      " SG_ A : 7|8@0- (0.5,0) [0|0] \"\" X\n SG_ B : 15|12@0+ (1,0) [0|0] \"\" X\n"
      " SG_ C : 19|4@0+ (1,0) [0|0] \"\" X\n SG_ D : 31|16@0- (0.01,-5) [0|0] \"\" X\n"
      " SG_ E : 47|6@0+ (1,0) [0|0] \"\" X\n SG_ F : 41|10@0- (2,0) [0|0] \"\" X\n"
      " SG_ G : 63|4@0+ (1,0) [0|0] \"\" X\n SG_ H : 59|4@0+ (1,0) [0|0] \"\" X\n",
      "motorola.dbc");
  DecodeLoop(state, dbc.messages[0]);
}
BENCHMARK(BM_DecodeMotorola_8signals);

/// The daemon's path: find the message by CAN ID, then decode (PUMP_FAST_I among 8 messages).
void BM_FindAndDecode_PumpthermDbc(benchmark::State& state) {
  const DbcCodec codec(PumpthermDbc());
  const auto frames = Frames();
  std::vector<double> values(8);
  std::size_t i = 0;
  for (auto _ : state) {
    const auto& f = frames[i++ & 255];
    const int index = codec.Find(0x100, false);
    benchmark::DoNotOptimize(codec.message(static_cast<std::size_t>(index))
                                 .Decode(std::span<const std::uint8_t>(f.data(), 8), values));
    benchmark::ClobberMemory();
  }
  state.SetItemsProcessed(static_cast<std::int64_t>(state.iterations()));
}
BENCHMARK(BM_FindAndDecode_PumpthermDbc);

/// Encoding PUMP_STATUS (6 signals) from physical values.
void BM_EncodePumpStatus_6signals(benchmark::State& state) {
  const MessageCodec codec(*PumpthermDbc().FindMessage("PUMP_STATUS"));
  std::vector<double> values = {21000, 2, 45.3, 22.1, 48.05, 7};
  std::array<std::uint8_t, 8> out{};
  for (auto _ : state) {
    values[0] += 2.0;
    benchmark::DoNotOptimize(codec.Encode(values, out));
    benchmark::ClobberMemory();
  }
  state.SetItemsProcessed(static_cast<std::int64_t>(state.iterations()));
}
BENCHMARK(BM_EncodePumpStatus_6signals);

/// Loading Model3CAN.dbc (384 kB, 148 messages): parse + compile every plan. The file is read
/// into memory once, outside the timing.
void BM_LoadModel3Dbc(benchmark::State& state) {
  const auto path = SourceDir() / ".." / "shared" / "data" / "dbc" / "model3dbc" / "Model3CAN.dbc";
  if (!std::filesystem::exists(path)) {
    state.SkipWithError("Model3CAN.dbc absent (../shared/data/dbc/model3dbc)");
    return;
  }
  const std::string text = ReadFile(path);
  for (auto _ : state) {
    Dbc dbc = ParseDbc(text, "Model3CAN.dbc");
    DbcCodec codec(dbc);
    benchmark::DoNotOptimize(codec.size());
  }
  state.SetBytesProcessed(static_cast<std::int64_t>(state.iterations() * text.size()));
}
BENCHMARK(BM_LoadModel3Dbc)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
