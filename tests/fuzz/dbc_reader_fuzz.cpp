// libFuzzer target: the DBC reader on arbitrary text. A DbcError is the expected answer to bad
// input; any other exception, a crash, a sanitizer report or a plan that cannot be compiled
// from an accepted file is a finding.
#include <cstdint>
#include <cstdlib>
#include <string_view>

#include "protocol/codec.hpp"
#include "protocol/dbc.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace pumptherm::protocol;
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  Dbc dbc;
  try {
    dbc = ParseDbc(text, "fuzz.dbc");
  } catch (const DbcError&) {
    return 0;
  }
  // Whatever the reader accepts, the codec must compile and decode without reading out of
  // bounds: every message on an all-ones frame of exactly its minimum length.
  const DbcCodec codec(dbc);
  for (std::size_t i = 0; i < codec.size(); ++i) {
    const MessageCodec& m = codec.message(i);
    if (m.min_bytes() > 64) std::abort();
    std::uint8_t frame[64];
    for (auto& b : frame) b = 0xFF;
    double values[512];
    if (m.signal_count() > 512) continue;
    if (m.Decode(std::span<const std::uint8_t>(frame, m.min_bytes()),
                 std::span<double>(values, m.signal_count())) != CodecStatus::kOk) {
      std::abort();
    }
  }
  return 0;
}
