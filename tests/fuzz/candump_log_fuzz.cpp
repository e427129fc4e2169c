// libFuzzer target: the candump log line parser (protocol/candump_log.hpp) on arbitrary text,
// line by line as the offline reader hands it lines. A parse failure must give a column inside
// the line (or one past its end) and a message; an accepted line must hold a frame within the
// CAN rules (len <= 8 classic, <= 64 FD; 11/29-bit id) and survive format -> parse unchanged.
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <string>
#include <string_view>

#include "protocol/candump_log.hpp"

namespace {

using namespace pumptherm::protocol;

void CheckLine(std::string_view line) {
  // A heap copy of exactly the line so ASan sees any read past its end.
  const std::string copy(line);
  const CandumpParse p = ParseCandumpLine(copy);
  if (p.skip) return;
  if (!p.ok) {
    if (p.error == nullptr || std::strlen(p.error) == 0 || p.column < 1 ||
        p.column > copy.size() + 1)
      std::abort();
    return;
  }
  const CanFrame& f = p.record.frame;
  if (f.len > (f.fd ? 64 : 8)) std::abort();
  if (f.id > (f.extended ? 0x1FFFFFFFu : 0x7FFu) && !f.error) std::abort();
  const std::string again = FormatCandumpLine(p.record.time_us, p.record.interface, f);
  const CandumpParse q = ParseCandumpLine(again);
  if (!q.ok || q.record.time_us != p.record.time_us || q.record.interface != p.record.interface)
    std::abort();
  const CanFrame& g = q.record.frame;
  if (g.id != f.id || g.extended != f.extended || g.fd != f.fd || g.remote != f.remote ||
      g.error != f.error || g.len != f.len || (f.fd && g.fd_flags != f.fd_flags)) {
    std::abort();
  }
  if (!f.remote && std::memcmp(g.data.data(), f.data.data(), f.len) != 0) std::abort();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  std::string_view text(reinterpret_cast<const char*>(data), size);
  while (!text.empty()) {
    const auto nl = text.find('\n');
    CheckLine(text.substr(0, nl));
    if (nl == std::string_view::npos) break;
    text.remove_prefix(nl + 1);
  }
  return 0;
}
