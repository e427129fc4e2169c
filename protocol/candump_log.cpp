#include "protocol/candump_log.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <iterator>

namespace pumptherm::protocol {
namespace {

constexpr std::uint32_t kErrorFlag = 0x20000000U;  // CAN_ERR_FLAG in linux/can.h

int HexValue(char c) noexcept {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  return -1;
}

CandumpParse Fail(std::size_t column, const char* what) noexcept {
  CandumpParse p;
  p.column = column;
  p.error = what;
  return p;
}

}  // namespace

CandumpParse ParseCandumpLine(std::string_view line) noexcept {
  // Trailing carriage return from logs written on other systems.
  while (!line.empty() && (line.back() == '\r' || line.back() == ' ' || line.back() == '\t')) {
    line.remove_suffix(1);
  }
  std::size_t i = 0;
  while (i < line.size() && (line[i] == ' ' || line[i] == '\t')) ++i;
  if (i == line.size() || line[i] == '#') {
    CandumpParse p;
    p.skip = true;
    return p;
  }
  if (line[i] != '(') return Fail(i + 1, "expected '(' starting the timestamp");
  ++i;
  std::int64_t seconds = 0;
  std::size_t digits = 0;
  while (i < line.size() && line[i] >= '0' && line[i] <= '9') {
    if (digits >= 12) return Fail(i + 1, "timestamp seconds too long");
    seconds = seconds * 10 + (line[i] - '0');
    ++i;
    ++digits;
  }
  if (digits == 0) return Fail(i + 1, "expected the timestamp's seconds");
  if (i >= line.size() || line[i] != '.') return Fail(i + 1, "expected '.' in the timestamp");
  ++i;
  std::int64_t micros = 0;
  digits = 0;
  while (i < line.size() && line[i] >= '0' && line[i] <= '9') {
    if (digits < 6) micros = micros * 10 + (line[i] - '0');
    ++i;
    ++digits;
  }
  if (digits == 0) return Fail(i + 1, "expected the timestamp's fraction");
  for (std::size_t d = digits; d < 6; ++d) micros *= 10;
  if (i >= line.size() || line[i] != ')') return Fail(i + 1, "expected ')' after the timestamp");
  ++i;
  if (i >= line.size() || line[i] != ' ') return Fail(i + 1, "expected a space after the timestamp");
  while (i < line.size() && line[i] == ' ') ++i;
  const std::size_t if_begin = i;
  while (i < line.size() && line[i] != ' ') ++i;
  if (i == if_begin) return Fail(i + 1, "expected an interface name");
  if (i - if_begin > 15) return Fail(if_begin + 1, "interface name longer than 15 characters");
  CandumpParse p;
  p.record.time_us = seconds * 1000000 + micros;
  p.record.interface = line.substr(if_begin, i - if_begin);
  while (i < line.size() && line[i] == ' ') ++i;

  // CAN ID: 3 hex digits (11 bit) or 8 hex digits (29 bit, or an error frame).
  const std::size_t id_begin = i;
  std::uint32_t id = 0;
  while (i < line.size() && line[i] != '#') {
    const int v = HexValue(line[i]);
    if (v < 0) return Fail(i + 1, "expected a hexadecimal CAN ID");
    if (i - id_begin >= 8) return Fail(i + 1, "CAN ID longer than 8 hex digits");
    id = (id << 4) | static_cast<std::uint32_t>(v);
    ++i;
  }
  const std::size_t id_len = i - id_begin;
  if (i >= line.size()) return Fail(i + 1, "expected '#' after the CAN ID");
  CanFrame& f = p.record.frame;
  if (id_len == 3) {
    if (id > 0x7FF) return Fail(id_begin + 1, "11-bit CAN ID above 7FF");
    f.id = id;
  } else if (id_len == 8) {
    if (id > (0x1FFFFFFFU | kErrorFlag)) {
      // Bits 30 and 31 are the RTR and EFF flags of struct can_frame; candump writes neither.
      return Fail(id_begin + 1, "CAN ID above 29 bits");
    }
    if (id & kErrorFlag) {
      f.error = true;
      f.id = id & 0x1FFFFFFFU;
    } else if (id > 0x1FFFFFFFU) {
      return Fail(id_begin + 1, "29-bit CAN ID above 1FFFFFFF");
    } else {
      f.extended = true;
      f.id = id;
    }
  } else {
    return Fail(id_begin + 1, "expected a CAN ID of 3 or 8 hex digits");
  }
  ++i;  // '#'
  std::size_t max_len = 8;
  if (i < line.size() && line[i] == '#') {
    // CAN FD: a flags nibble follows the second '#'.
    ++i;
    if (i >= line.size()) return Fail(i + 1, "expected the CAN FD flags nibble");
    const int flags = HexValue(line[i]);
    if (flags < 0) return Fail(i + 1, "expected a hexadecimal CAN FD flags nibble");
    f.fd = true;
    f.fd_flags = static_cast<std::uint8_t>(flags);
    max_len = kMaxFrameBytes;
    ++i;
  } else if (i < line.size() && (line[i] == 'R' || line[i] == 'r')) {
    f.remote = true;
    ++i;
    if (i < line.size()) {
      const int v = HexValue(line[i]);
      if (v < 0 || v > 8) return Fail(i + 1, "expected a remote frame length 0 to 8");
      f.len = static_cast<std::uint8_t>(v);
      ++i;
    }
    if (i != line.size()) return Fail(i + 1, "unexpected text after a remote frame");
    p.ok = true;
    return p;
  }
  std::size_t n = 0;
  while (i < line.size()) {
    if (line[i] == '.') {
      ++i;
      continue;
    }
    if (line[i] == '_') break;  // classic CAN len8_dlc suffix: not used here
    const int hi = HexValue(line[i]);
    if (hi < 0) return Fail(i + 1, "expected hexadecimal payload bytes");
    if (i + 1 >= line.size()) return Fail(i + 2, "payload byte cut in half");
    const int lo = HexValue(line[i + 1]);
    if (lo < 0) return Fail(i + 2, "expected hexadecimal payload bytes");
    if (n >= max_len) return Fail(i + 1, f.fd ? "payload longer than 64 bytes" : "payload longer than 8 bytes");
    f.data[n++] = static_cast<std::uint8_t>((hi << 4) | lo);
    i += 2;
  }
  if (i < line.size() && line[i] == '_') {
    // "_<dlc>" after a full 8-byte classic frame; accept and ignore.
    if (f.fd || n != 8 || i + 2 != line.size() || HexValue(line[i + 1]) < 9) {
      return Fail(i + 1, "malformed length suffix");
    }
  }
  if (f.fd) {
    static constexpr std::size_t kFdLengths[] = {0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64};
    bool valid = false;
    for (std::size_t l : kFdLengths) valid = valid || (l == n);
    if (!valid) return Fail(i + 1, "CAN FD payload length is not a valid FD length");
  }
  f.len = static_cast<std::uint8_t>(n);
  p.ok = true;
  return p;
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
    fmt::format_to(std::back_inserter(out), "({:010d}.{:06d}) ", time_us / 1000000, time_us % 1000000);
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
