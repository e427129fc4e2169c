#include "protocol/candump_log.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <iterator>

namespace pumptherm::protocol {
namespace {

constexpr std::uint32_t kErrorFlag = 0x20000000U;  // CAN_ERR_FLAG in linux/can.h

/// Value of each byte as a hex digit, -1 for the others: one load per digit instead of three
/// range tests (the log format is almost all hex digits).
constexpr std::array<std::int8_t, 256> kHexValues = [] {
  std::array<std::int8_t, 256> t{};
  for (auto& v : t) v = -1;
  for (int c = 0; c < 10; ++c) t[static_cast<std::size_t>('0' + c)] = static_cast<std::int8_t>(c);
  for (int c = 0; c < 6; ++c) {
    t[static_cast<std::size_t>('a' + c)] = static_cast<std::int8_t>(10 + c);
    t[static_cast<std::size_t>('A' + c)] = static_cast<std::int8_t>(10 + c);
  }
  return t;
}();

int HexValue(char c) noexcept { return kHexValues[static_cast<unsigned char>(c)]; }

bool IsBlank(char c) noexcept { return c == ' ' || c == '\t'; }

std::size_t SkipBlanks(std::string_view s, std::size_t i) noexcept {
  while (i < s.size() && IsBlank(s[i])) ++i;
  return i;
}

CandumpParse Fail(std::size_t column, const char* what) noexcept {
  CandumpParse p;
  p.column = column;
  p.error = what;
  return p;
}

// The parts below return nullptr on success, else what was expected, with `i` left at the
// (0-based) position of the problem.

/// "(SECONDS.FRACTION)" from s[i] == '(' to just past ')': candump's "%010lu.%06lu" (-l, -L,
/// -t a) and "%03lu.%06lu" (-t z, -t d); asc2log's "%lu.%06lu".
const char* ParseTimestamp(std::string_view s, std::size_t& i, std::int64_t& time_us) noexcept {
  ++i;  // '('
  std::int64_t seconds = 0;
  std::size_t digits = 0;
  while (i < s.size() && s[i] >= '0' && s[i] <= '9') {
    if (digits >= 12) return "timestamp seconds too long";
    seconds = seconds * 10 + (s[i] - '0');
    ++i;
    ++digits;
  }
  if (digits == 0) return "expected the timestamp's seconds";
  if (i < s.size() && s[i] == '-') {
    return "a date stamp (candump -t A, local time) cannot be read: record with -l, -L or -t a";
  }
  if (i >= s.size() || s[i] != '.') return "expected '.' in the timestamp";
  ++i;
  std::int64_t micros = 0;
  digits = 0;
  while (i < s.size() && s[i] >= '0' && s[i] <= '9') {
    if (digits < 6) micros = micros * 10 + (s[i] - '0');
    ++i;
    ++digits;
  }
  if (digits == 0) return "expected the timestamp's fraction";
  for (std::size_t d = digits; d < 6; ++d) micros *= 10;
  if (i >= s.size() || s[i] != ')') return "expected ')' after the timestamp";
  ++i;
  time_us = seconds * 1000000 + micros;
  return nullptr;
}

/// A CAN ID ending at the first `stop` (or the end of the line): 3 hex digits (11 bit) or 8
/// (29 bit, or an error frame with CAN_ERR_FLAG). Leaves `i` at the stop.
const char* ParseId(std::string_view s, std::size_t& i, char stop, CanFrame& f) noexcept {
  const std::size_t begin = i;
  std::uint32_t id = 0;
  while (i < s.size() && s[i] != stop) {
    const int v = HexValue(s[i]);
    if (v < 0) return "expected a hexadecimal CAN ID";
    if (i - begin >= 8) return "CAN ID longer than 8 hex digits";
    id = (id << 4) | static_cast<std::uint32_t>(v);
    ++i;
  }
  const std::size_t len = i - begin;
  if (len == 3) {
    if (id > 0x7FF) {
      i = begin;
      return "11-bit CAN ID above 7FF";
    }
    f.id = id;
    return nullptr;
  }
  const char* error = nullptr;
  if (len != 8) {
    error = "expected a CAN ID of 3 or 8 hex digits";
  } else if (id > (0x1FFFFFFFU | kErrorFlag)) {
    // Bits 30 and 31 are the RTR and EFF flags of struct can_frame; candump writes neither.
    error = "CAN ID above 29 bits";
  } else if (!(id & kErrorFlag) && id > 0x1FFFFFFFU) {
    error = "29-bit CAN ID above 1FFFFFFF";
  }
  if (error) {
    i = begin;
    return error;
  }
  if (id & kErrorFlag) {
    f.error = true;
    f.id = id & 0x1FFFFFFFU;
  } else {
    f.extended = true;
    f.id = id;
  }
  return nullptr;
}

bool ValidFdLength(std::size_t n) noexcept {
  static constexpr std::size_t kFdLengths[] = {0, 1,  2,  3,  4,  5,  6,  7,
                                               8, 12, 16, 20, 24, 32, 48, 64};
  for (std::size_t l : kFdLengths) {
    if (l == n) return true;
  }
  return false;
}

/// The log format's frame after the '#': "R" and a length digit (remote), "#" and a flags
/// nibble (CAN FD), then the payload in hex pairs, optionally dotted ("11.22"), classic frames
/// optionally with a "_<dlc>" suffix.
const char* ParseCompactPayload(std::string_view s, std::size_t& i, CanFrame& f) noexcept {
  std::size_t max_len = 8;
  if (i < s.size() && s[i] == '#') {
    ++i;
    if (i >= s.size()) return "expected the CAN FD flags nibble";
    const int flags = HexValue(s[i]);
    if (flags < 0) return "expected a hexadecimal CAN FD flags nibble";
    f.fd = true;
    f.fd_flags = static_cast<std::uint8_t>(flags);
    max_len = kMaxFrameBytes;
    ++i;
  } else if (i < s.size() && (s[i] == 'R' || s[i] == 'r')) {
    f.remote = true;
    ++i;
    if (i < s.size()) {
      const int v = HexValue(s[i]);
      if (v < 0 || v > 8) return "expected a remote frame length 0 to 8";
      f.len = static_cast<std::uint8_t>(v);
      ++i;
    }
    return i == s.size() ? nullptr : "unexpected text after a remote frame";
  }
  std::size_t n = 0;
  while (i < s.size() && s[i] != '_') {
    if (s[i] == '.') {
      ++i;
      continue;
    }
    const int hi = HexValue(s[i]);
    if (hi < 0) return "expected hexadecimal payload bytes";
    if (i + 1 >= s.size() || HexValue(s[i + 1]) < 0) {
      ++i;
      return i == s.size() ? "payload byte cut in half" : "expected hexadecimal payload bytes";
    }
    if (n >= max_len) return f.fd ? "payload longer than 64 bytes" : "payload longer than 8 bytes";
    f.data[n++] = static_cast<std::uint8_t>((hi << 4) | HexValue(s[i + 1]));
    i += 2;
  }
  // "_<dlc>" after a full 8-byte classic frame (len8_dlc 9..F): accepted and ignored.
  if (i < s.size() && (f.fd || n != 8 || i + 2 != s.size() || HexValue(s[i + 1]) < 9)) {
    return "malformed length suffix";
  }
  i = s.size();
  if (f.fd && !ValidFdLength(n)) return "CAN FD payload length is not a valid FD length";
  f.len = static_cast<std::uint8_t>(n);
  return nullptr;
}

/// candump -x's "RX - -" / "TX B E" after the interface: direction, then the CAN FD flags
/// BRS and ESI ('-' when clear). Leaves `i` on the CAN ID.
const char* ParseExtraInfo(std::string_view s, std::size_t& i, CandumpRecord& r) noexcept {
  r.direction = s[i];
  i += 2;
  i = SkipBlanks(s, i);
  const bool brs = i < s.size() && s[i] == 'B';
  if (i >= s.size() || (s[i] != 'B' && s[i] != '-'))
    return "expected 'B' or '-' (candump -x flags)";
  i = SkipBlanks(s, i + 1);
  const bool esi = i < s.size() && s[i] == 'E';
  if (i >= s.size() || (s[i] != 'E' && s[i] != '-'))
    return "expected 'E' or '-' (candump -x flags)";
  r.frame.fd_flags = static_cast<std::uint8_t>((brs ? 1 : 0) | (esi ? 2 : 0));
  i = SkipBlanks(s, i + 1);
  return nullptr;
}

/// "[8]" (classic) or "[08]" (CAN FD): the length candump prints after the ID.
const char* ParseBracketLength(std::string_view s, std::size_t& i, CanFrame& f) noexcept {
  if (i >= s.size() || s[i] != '[')
    return "expected '[' and the length after the CAN ID (or '#' of the log format)";
  ++i;
  std::size_t len = 0, digits = 0;
  while (i < s.size() && s[i] >= '0' && s[i] <= '9' && digits < 2) {
    len = len * 10 + static_cast<std::size_t>(s[i] - '0');
    ++i;
    ++digits;
  }
  if (digits == 0 || i >= s.size() || s[i] != ']')
    return "expected the length in brackets, as [8] or [64]";
  f.fd = digits == 2;
  if (f.fd ? !ValidFdLength(len) : len > 8) return "frame length out of range";
  f.len = static_cast<std::uint8_t>(len);
  ++i;
  return nullptr;
}

/// The screen format's frame from the CAN ID on ("123   [8]  11 22 ..."), as can-utils'
/// sprint_long_canframe writes it, with candump's "remote request", the ASCII column of -a
/// ("'..3DUf'") and an error frame's "ERRORFRAME" after the bytes.
const char* ParseLongFrame(std::string_view s, std::size_t& i, CandumpRecord& r) noexcept {
  CanFrame& f = r.frame;
  if (i + 2 < s.size() && (s[i] == 'R' || s[i] == 'T') && s[i + 1] == 'X' && IsBlank(s[i + 2])) {
    if (const char* e = ParseExtraInfo(s, i, r)) return e;
  }
  const std::uint8_t flags = f.fd_flags;
  if (const char* e = ParseId(s, i, ' ', f)) return e;
  i = SkipBlanks(s, i);
  if (const char* e = ParseBracketLength(s, i, f)) return e;
  f.fd_flags = f.fd ? flags : 0;
  i = SkipBlanks(s, i);
  if (!f.fd && s.substr(i) == "remote request") {
    f.remote = true;
    i = s.size();
    return nullptr;
  }
  std::size_t n = 0;
  while (i < s.size() && s[i] != '\'' && s.substr(i) != "ERRORFRAME") {
    const int hi = HexValue(s[i]);
    const int lo = i + 1 < s.size() ? HexValue(s[i + 1]) : -1;
    if (hi < 0 || lo < 0 || (i + 2 < s.size() && !IsBlank(s[i + 2])))
      return "expected a payload byte (two hex digits)";
    if (n >= f.len) return "more payload bytes than the length in brackets";
    f.data[n++] = static_cast<std::uint8_t>((hi << 4) | lo);
    i = SkipBlanks(s, i + 2);
  }
  if (n != f.len) return "fewer payload bytes than the length in brackets";
  i = s.size();
  return nullptr;
}

}  // namespace

CandumpParse ParseCandumpLine(std::string_view line) noexcept {
  // Trailing carriage return from logs written on other systems.
  while (!line.empty() && (line.back() == '\r' || IsBlank(line.back()))) line.remove_suffix(1);
  std::size_t i = SkipBlanks(line, 0);
  if (i == line.size() || line[i] == '#') {
    CandumpParse p;
    p.skip = true;
    return p;
  }
  CandumpParse p;
  CandumpRecord& r = p.record;
  if (line[i] == '(') {
    if (const char* e = ParseTimestamp(line, i, r.time_us)) return Fail(i + 1, e);
    if (i >= line.size() || !IsBlank(line[i]))
      return Fail(i + 1, "expected a space after the timestamp");
  } else {
    r.has_time = false;  // the screen format without -t
  }
  i = SkipBlanks(line, i);
  const std::size_t if_begin = i;
  while (i < line.size() && !IsBlank(line[i])) ++i;
  if (i == if_begin) return Fail(i + 1, "expected an interface name");
  r.interface = line.substr(if_begin, i - if_begin);
  if (!r.has_time && r.interface.find(')') != std::string_view::npos) {
    return Fail(if_begin + 1, "expected '(' starting the timestamp");
  }
  if (r.interface.size() > 15) {
    return Fail(if_begin + 1,
                r.has_time ? "interface name longer than 15 characters"
                           : "not a candump line: expected '(' and a timestamp, or an interface "
                             "(at most 15 characters)");
  }
  i = SkipBlanks(line, i);
  std::size_t token_end = i;
  while (token_end < line.size() && !IsBlank(line[token_end]) && line[token_end] != '#')
    ++token_end;
  if (token_end < line.size() && line[token_end] == '#') {
    // The log format (-l, -L, asc2log): "ID#DATA", then " R" or " T" with -x (received, sent).
    if (line.size() >= 2 && IsBlank(line[line.size() - 2]) &&
        (line.back() == 'R' || line.back() == 'T')) {
      r.direction = line.back();
      line.remove_suffix(2);
      while (IsBlank(line.back())) line.remove_suffix(1);
    }
    if (const char* e = ParseId(line, i, '#', r.frame)) return Fail(i + 1, e);
    ++i;  // '#'
    if (const char* e = ParseCompactPayload(line, i, r.frame)) return Fail(i + 1, e);
  } else {
    const std::size_t frame_begin = i;
    if (const char* e = ParseLongFrame(line, i, r)) {
      // Without a timestamp and a CAN ID after the first word, it is not candump's output at all.
      if (!r.has_time && i <= token_end && i >= frame_begin) {
        return Fail(if_begin + 1,
                    "not a candump line: expected '(' and a timestamp, or an interface, a CAN ID "
                    "and [length]");
      }
      return Fail(i + 1, e);
    }
  }
  p.ok = true;
  return p;
}

const char* CandumpTimeBaseName(CandumpTimeBase base) noexcept {
  switch (base) {
    case CandumpTimeBase::kAbsolute:
      return "Unix time";
    case CandumpTimeBase::kSinceFirst:
      return "the time since the first frame (candump -t z)";
    case CandumpTimeBase::kSincePrevious:
      return "the time since the previous frame (candump -t d)";
  }
  return "";
}

CandumpTimeBase ClassifyCandumpStamps(const std::int64_t* stamps_us, std::size_t count) noexcept {
  constexpr std::int64_t kUnixFrom_us = 1'000'000'000'000'000;  // 1e9 s: 2001-09-09
  for (std::size_t i = 0; i < count; ++i) {
    if (stamps_us[i] >= kUnixFrom_us) return CandumpTimeBase::kAbsolute;
  }
  if (count == 0) return CandumpTimeBase::kAbsolute;  // nothing to read otherwise
  if (count < 3) return CandumpTimeBase::kSinceFirst;
  // The first step is the same in both (-t d's first stamp is 0, its second the first gap).
  std::size_t up = 0, down = 0;
  for (std::size_t i = 2; i < count; ++i) {
    up += stamps_us[i] > stamps_us[i - 1];
    down += stamps_us[i] < stamps_us[i - 1];
  }
  return (up == 0 || 10 * down > up) ? CandumpTimeBase::kSincePrevious
                                     : CandumpTimeBase::kSinceFirst;
}

namespace {

/// Appends `v` in decimal, zero-padded to at least `width` digits.
void AppendDecimal(std::string& out, std::uint64_t v, int width) {
  char digits[24];
  int n = 0;
  do {
    digits[n++] = static_cast<char>('0' + v % 10);
    v /= 10;
  } while (v != 0);
  for (int k = n; k < width; ++k) out += '0';
  while (n > 0) out += digits[--n];
}

/// Appends `v` in upper-case hexadecimal, zero-padded to at least `width` digits.
void AppendHex(std::string& out, std::uint32_t v, int width) {
  static constexpr char kHex[] = "0123456789ABCDEF";
  char digits[8];
  int n = 0;
  do {
    digits[n++] = kHex[v & 0xF];
    v >>= 4;
  } while (v != 0);
  for (int k = n; k < width; ++k) out += '0';
  while (n > 0) out += digits[--n];
}

}  // namespace

void AppendCandumpLine(std::string& out, std::int64_t time_us, std::string_view interface,
                       const CanFrame& frame) {
  static constexpr char kHex[] = "0123456789ABCDEF";
  if (time_us >= 0) {
    out += '(';
    AppendDecimal(out, static_cast<std::uint64_t>(time_us / 1000000), 10);
    out += '.';
    AppendDecimal(out, static_cast<std::uint64_t>(time_us % 1000000), 6);
    out += ") ";
  } else {  // not from a clock; formatted as before (C++ division: "-000000001.-00001")
    fmt::format_to(std::back_inserter(out), "({:010d}.{:06d}) ", time_us / 1000000,
                   time_us % 1000000);
  }
  out.append(interface);
  out += ' ';
  if (frame.error) {
    AppendHex(out, frame.id | kErrorFlag, 8);
  } else {
    AppendHex(out, frame.id, frame.extended ? 8 : 3);
  }
  out += '#';
  if (frame.remote) {
    // A remote frame's length is part of it: candump writes "R" and a length digit if not 0.
    out += 'R';
    if (frame.len > 0 && frame.len <= 8) out += static_cast<char>('0' + frame.len);
    return;
  }
  if (frame.fd) {
    out += '#';
    out += kHex[frame.fd_flags & 0xF];
  }
  const std::size_t len = std::min<std::size_t>(frame.len, frame.data.size());
  for (std::size_t k = 0; k < len; ++k) {
    out += kHex[frame.data[k] >> 4];
    out += kHex[frame.data[k] & 0xF];
  }
}

std::string FormatCandumpLine(std::int64_t time_us, std::string_view interface,
                              const CanFrame& frame) {
  std::string out;
  out.reserve(48 + interface.size() + 2 * static_cast<std::size_t>(frame.len));
  AppendCandumpLine(out, time_us, interface, frame);
  return out;
}

}  // namespace pumptherm::protocol
