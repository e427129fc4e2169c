// libFuzzer target: decoding arbitrary frames with the plans of protocol/pumptherm.dbc and
// tests/protocol/candied/features.dbc (IEEE, 64-bit, CAN FD, extended multiplexing).
// Input: byte 0 selects the message, the rest is the payload (any length, also too short).
// Findings: a crash or sanitizer report (e.g. a read past the payload), a short frame that is
// not rejected, or a decode -> encode -> decode that does not give the same raw bits back.
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "protocol/codec.hpp"
#include "protocol/dbc.hpp"

namespace {

using namespace pumptherm::protocol;

struct Plans {
  std::vector<Dbc> dbcs;
  std::vector<std::pair<const DbcMessage*, MessageCodec>> messages;
};

std::string Read(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    std::fprintf(stderr, "frame_decode_fuzz: cannot open %s\n", path.c_str());
    std::abort();
  }
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

const Plans& GetPlans() {
  static const Plans plans = [] {
    Plans p;
    const char* env = std::getenv("PUMPTHERM_SOURCE_DIR");
    const std::string root = env != nullptr ? env : PUMPTHERM_SOURCE_DIR_DEFAULT;
    for (const char* rel : {"/protocol/pumptherm.dbc", "/tests/protocol/candied/features.dbc"}) {
      p.dbcs.push_back(ParseDbc(Read(root + rel), rel));
    }
    for (const auto& dbc : p.dbcs) {
      for (const auto& m : dbc.messages) p.messages.emplace_back(&m, MessageCodec(m));
    }
    return p;
  }();
  return plans;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  const Plans& plans = GetPlans();
  const auto& [message, codec] = plans.messages[data[0] % plans.messages.size()];
  // Copy to a heap buffer of exactly the payload's length so ASan sees any over-read.
  const std::vector<std::uint8_t> payload(data + 1, data + size);
  std::vector<double> values(codec.signal_count());
  const CodecStatus status = codec.Decode(payload, values);
  if (payload.size() < codec.min_bytes()) {
    if (status != CodecStatus::kTooShort) std::abort();
    return 0;
  }
  if (status != CodecStatus::kOk) std::abort();
  std::vector<std::uint8_t> out(codec.min_bytes());
  if (codec.Encode(values, out).status != CodecStatus::kOk) std::abort();
  for (std::size_t i = 0; i < codec.signal_count(); ++i) {
    const DbcSignal& s = message->signals[i];
    if (std::isnan(values[i]) || s.value_type != SignalValueType::kInteger || s.length_bits > 53)
      continue;
    if (codec.RawBits(out, i) != codec.RawBits(payload, i)) std::abort();
  }
  return 0;
}
