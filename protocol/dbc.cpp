#include "protocol/dbc.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <limits>
#include <set>

namespace pumptherm::protocol {

DbcError::DbcError(std::string file, int line, int column, const std::string& what)
    : std::runtime_error(fmt::format("{}:{}:{}: {}", file, line, column, what)),
      file_(std::move(file)),
      detail_(what),
      line_(line),
      column_(column) {}

int DbcMessage::FindSignal(std::string_view signal_name) const noexcept {
  for (std::size_t i = 0; i < signals.size(); ++i) {
    if (signals[i].name == signal_name) return static_cast<int>(i);
  }
  return -1;
}

std::uint32_t SignalEndByte(const DbcSignal& s) noexcept {
  if (s.byte_order == ByteOrder::kLittleEndian) return (s.start_bit + s.length_bits - 1) / 8 + 1;
  // Motorola: the MSB sits at start_bit; bits run down within a byte, then on to the next byte.
  const std::uint32_t in_first = s.start_bit % 8 + 1;
  std::uint32_t last_byte = s.start_bit / 8;
  if (s.length_bits > in_first) last_byte += (s.length_bits - in_first + 7) / 8;
  return last_byte + 1;
}

const DbcMessage* Dbc::FindMessage(std::string_view name) const noexcept {
  for (const auto& m : messages) {
    if (m.name == name) return &m;
  }
  return nullptr;
}

const DbcMessage* Dbc::FindMessage(std::uint32_t id, bool extended) const noexcept {
  for (const auto& m : messages) {
    if (m.id == id && m.extended == extended) return &m;
  }
  return nullptr;
}

namespace {

constexpr std::uint32_t kExtendedFlag = 0x80000000u;
/// CANdb++ puts signals that belong to no message into this pseudo-message.
constexpr std::uint32_t kIndependentSignalsId = 0xC0000000u;

enum class TokenKind { kEnd, kIdentifier, kNumber, kString, kPunct };

struct Token {
  TokenKind kind = TokenKind::kEnd;
  std::string_view text;  ///< for kString: the raw text between the quotes (escapes kept)
  int line = 1;
  int column = 1;
};

/// Top-level keywords: a node list (`BU_`) or a receiver list ends at one of these.
bool IsKeyword(std::string_view s) {
  static constexpr std::array<std::string_view, 36> kKeywords = {"VERSION",
                                                                 "NS_",
                                                                 "BS_",
                                                                 "BU_",
                                                                 "BO_",
                                                                 "SG_",
                                                                 "CM_",
                                                                 "BA_DEF_",
                                                                 "BA_DEF_DEF_",
                                                                 "BA_",
                                                                 "VAL_",
                                                                 "VAL_TABLE_",
                                                                 "SIG_VALTYPE_",
                                                                 "SG_MUL_VAL_",
                                                                 "EV_",
                                                                 "ENVVAR_DATA_",
                                                                 "SGTYPE_",
                                                                 "SGTYPE_VAL_",
                                                                 "BA_DEF_SGTYPE_",
                                                                 "BA_SGTYPE_",
                                                                 "SIG_TYPE_REF_",
                                                                 "SIG_GROUP_",
                                                                 "SIGTYPE_VALTYPE_",
                                                                 "BO_TX_BU_",
                                                                 "BA_DEF_REL_",
                                                                 "BA_REL_",
                                                                 "BA_DEF_DEF_REL_",
                                                                 "BU_SG_REL_",
                                                                 "BU_EV_REL_",
                                                                 "BU_BO_REL_",
                                                                 "CAT_DEF_",
                                                                 "CAT_",
                                                                 "FILTER",
                                                                 "NS_DESC_",
                                                                 "EV_DATA_",
                                                                 "ENVVAR_DATA"};
  return std::find(kKeywords.begin(), kKeywords.end(), s) != kKeywords.end();
}

bool IsIdentStart(char c) { return (c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || c == '_'; }
bool IsIdentChar(char c) { return IsIdentStart(c) || (c >= '0' && c <= '9'); }
bool IsDigit(char c) { return c >= '0' && c <= '9'; }

std::string DescribeToken(const Token& t) {
  switch (t.kind) {
    case TokenKind::kEnd:
      return "end of file";
    case TokenKind::kString:
      return fmt::format("string \"{}\"", t.text.substr(0, 40));
    default:
      return fmt::format("'{}'", t.text.substr(0, 40));
  }
}

class Lexer {
 public:
  Lexer(std::string_view text, std::string_view file_name) : text_(text), file_name_(file_name) {}

  const Token& Peek() {
    if (!has_peek_) {
      peek_ = Scan();
      has_peek_ = true;
    }
    return peek_;
  }
  Token Next() {
    Peek();
    has_peek_ = false;
    last_ = peek_;
    return peek_;
  }
  /// The token Next() returned last.
  const Token& last() const { return last_; }
  /// Puts the token Next() returned last back, so the next statement starts with it. Only
  /// right after Next() (nothing peeked since).
  bool Unget() {
    if (has_peek_) return false;
    peek_ = last_;
    has_peek_ = true;
    return true;
  }
  /// Whether the lexer itself failed (an unterminated string): nothing after it can be read.
  bool failed() const { return failed_; }

 private:
  char At(std::size_t i) const { return i < text_.size() ? text_[i] : '\0'; }
  void Advance() {
    if (text_[pos_] == '\n') {
      ++line_;
      column_ = 1;
    } else {
      ++column_;
    }
    ++pos_;
  }

  Token Scan() {
    // Whitespace and `//` comments.
    for (;;) {
      while (pos_ < text_.size() &&
             (text_[pos_] == ' ' || text_[pos_] == '\t' || text_[pos_] == '\r' ||
              text_[pos_] == '\n' || text_[pos_] == '\f' || text_[pos_] == '\v')) {
        Advance();
      }
      if (At(pos_) == '/' && At(pos_ + 1) == '/') {
        while (pos_ < text_.size() && text_[pos_] != '\n') Advance();
        continue;
      }
      break;
    }
    Token t;
    t.line = line_;
    t.column = column_;
    if (pos_ >= text_.size()) return t;
    const std::size_t start = pos_;
    const char c = text_[pos_];
    if (c == '"') {
      Advance();
      const std::size_t body = pos_;
      while (pos_ < text_.size() && text_[pos_] != '"') {
        if (text_[pos_] == '\\' && pos_ + 1 < text_.size()) Advance();
        Advance();
      }
      if (pos_ >= text_.size()) {
        failed_ = true;
        throw DbcError(std::string(file_name_), t.line, t.column, "unterminated string");
      }
      t.kind = TokenKind::kString;
      t.text = text_.substr(body, pos_ - body);
      Advance();
      return t;
    }
    const bool signed_number =
        (c == '-' || c == '+') &&
        (IsDigit(At(pos_ + 1)) || (At(pos_ + 1) == '.' && IsDigit(At(pos_ + 2))));
    if (IsDigit(c) || signed_number || (c == '.' && IsDigit(At(pos_ + 1)))) {
      if (signed_number) Advance();
      while (IsDigit(At(pos_))) Advance();
      if (!signed_number && IsDigit(c) && IsIdentStart(At(pos_)) && At(pos_) != 'e' &&
          At(pos_) != 'E') {
        // Real files name things "2017_5" or "5_SEC_TIMER": digits then letters is a name.
        while (IsIdentChar(At(pos_))) Advance();
        t.kind = TokenKind::kIdentifier;
        t.text = text_.substr(start, pos_ - start);
        return t;
      }
      if (At(pos_) == '.') {
        Advance();
        while (IsDigit(At(pos_))) Advance();
      }
      if ((At(pos_) == 'e' || At(pos_) == 'E') &&
          (IsDigit(At(pos_ + 1)) ||
           ((At(pos_ + 1) == '-' || At(pos_ + 1) == '+') && IsDigit(At(pos_ + 2))))) {
        Advance();
        if (At(pos_) == '-' || At(pos_) == '+') Advance();
        while (IsDigit(At(pos_))) Advance();
      }
      t.kind = TokenKind::kNumber;
      t.text = text_.substr(start, pos_ - start);
      return t;
    }
    if (IsIdentStart(c)) {
      while (IsIdentChar(At(pos_))) Advance();
      t.kind = TokenKind::kIdentifier;
      t.text = text_.substr(start, pos_ - start);
      return t;
    }
    Advance();
    t.kind = TokenKind::kPunct;
    t.text = text_.substr(start, 1);
    return t;
  }

  std::string_view text_;
  std::string_view file_name_;
  std::size_t pos_ = 0;
  int line_ = 1;
  int column_ = 1;
  Token peek_;
  Token last_;
  bool has_peek_ = false;
  bool failed_ = false;
};

/// Undoes the DBC string escapes (\" and \\).
std::string Unescape(std::string_view s) {
  std::string out;
  out.reserve(s.size());
  for (std::size_t i = 0; i < s.size(); ++i) {
    if (s[i] == '\\' && i + 1 < s.size() && (s[i + 1] == '"' || s[i + 1] == '\\')) ++i;
    out.push_back(s[i]);
  }
  return out;
}

struct PendingMuxValues {
  std::uint32_t message_id_raw;
  std::string signal;
  std::string switch_name;
  std::vector<MuxRange> ranges;
  int line;
  int column;
};

struct PendingAttribute {
  std::string name;
  DbcAttributeDefinition::Object object;
  std::string node;
  std::uint32_t message_id_raw = 0;
  std::string signal;
  DbcAttributeValue value;
  int line;
  int column;
};

class Parser {
 public:
  Parser(std::string_view text, std::string_view file_name) : lex_(text, file_name) {
    dbc_.file_name = std::string(file_name);
  }

  Dbc Parse() {
    std::optional<DbcError> first_error;
    while (lex_.Peek().kind != TokenKind::kEnd) {
      const Token kw = lex_.Peek();
      try {
        Statement();
      } catch (const DbcError& e) {
        if (lex_.failed()) throw;
        if (!first_error) first_error = e;
        Recover(kw, e);
      }
    }
    // A file of which nothing loads is not a DBC with warnings: report its first error.
    if (first_error && dbc_.messages.empty()) throw *first_error;
    Resolve();
    return std::move(dbc_);
  }

 private:
  [[noreturn]] void Fail(const Token& at, const std::string& expected) {
    throw DbcError(dbc_.file_name, at.line, at.column,
                   fmt::format("expected {}, found {}", expected, DescribeToken(at)));
  }
  [[noreturn]] void FailAt(int line, int column, const std::string& what) {
    throw DbcError(dbc_.file_name, line, column, what);
  }
  void Problem(int line, int column, std::string message) {
    dbc_.problems.push_back({line, column, std::move(message)});
  }

  /// A reference to the pseudo-message of independent signals or to a message skipped as
  /// malformed: nothing to attach it to, and nothing new to report.
  bool Ignored(std::uint32_t raw_id) const {
    return raw_id == kIndependentSignalsId || skipped_ids_.contains(raw_id);
  }

  /// Warn-and-skip, as canmatrix and opendbc's parser do with real files: the malformed
  /// statement (a BO_ with its SG_ lines, or one SG_) becomes a problem at the place it broke,
  /// and reading goes on at the next statement: after a ';', or at the next keyword on a later
  /// line (a statement missing its ';', like "CM_ ... \"text\"" then the next CM_).
  void Recover(const Token& kw, const DbcError& e) {
    const char* skipped = "statement skipped";
    if (kw.kind == TokenKind::kIdentifier && kw.text == "BO_") {
      skipped = "message and its signals skipped";
      current_message_ = -1;
      skipping_signals_ = true;
      if (message_raw_id_) skipped_ids_.insert(*message_raw_id_);
    } else if (kw.kind == TokenKind::kIdentifier && kw.text == "SG_") {
      skipped = "signal skipped";
    }
    if (e.line() != kw.line && kw.kind == TokenKind::kIdentifier) {
      Problem(e.line(), e.column(),
              fmt::format("{}; the {} of line {} skipped", e.detail(), kw.text, kw.line));
    } else {
      Problem(e.line(), e.column(), fmt::format("{}; {}", e.detail(), skipped));
    }
    const Token last = lex_.last();
    const bool consumed_more = last.line != kw.line || last.column != kw.column;
    if (last.kind == TokenKind::kPunct && last.text[0] == ';') return;
    if (consumed_more && last.kind == TokenKind::kIdentifier && IsKeyword(last.text) &&
        last.line > kw.line && lex_.Unget()) {
      return;  // the failing token starts the next statement
    }
    for (;;) {
      const Token t = lex_.Peek();
      if (t.kind == TokenKind::kEnd) return;
      if (t.kind == TokenKind::kIdentifier && IsKeyword(t.text) && t.line > last.line) return;
      lex_.Next();
      if (t.kind == TokenKind::kPunct && t.text[0] == ';') return;
    }
  }

  Token Expect(TokenKind kind, const char* what) {
    Token t = lex_.Next();
    if (t.kind != kind) Fail(t, what);
    return t;
  }
  void ExpectPunct(char c) {
    Token t = lex_.Next();
    if (t.kind != TokenKind::kPunct || t.text[0] != c) Fail(t, fmt::format("'{}'", c));
  }
  bool AcceptPunct(char c) {
    const Token& t = lex_.Peek();
    if (t.kind == TokenKind::kPunct && t.text[0] == c) {
      lex_.Next();
      return true;
    }
    return false;
  }
  bool PeekIdentifier(std::string_view s) {
    const Token& t = lex_.Peek();
    return t.kind == TokenKind::kIdentifier && t.text == s;
  }

  double Number(const char* what) {
    Token t = Expect(TokenKind::kNumber, what);
    std::string_view s = t.text;
    if (!s.empty() && s[0] == '+') s.remove_prefix(1);
    double v = 0.0;
    auto [p, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
    if (ec != std::errc() || p != s.data() + s.size()) Fail(t, what);
    return v;
  }
  std::int64_t Integer(const char* what) {
    Token t = Expect(TokenKind::kNumber, what);
    std::string_view s = t.text;
    if (!s.empty() && s[0] == '+') s.remove_prefix(1);
    std::int64_t v = 0;
    auto [p, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
    if (ec != std::errc() || p != s.data() + s.size()) Fail(t, what);
    return v;
  }
  std::uint64_t Unsigned(const char* what) {
    Token t = Expect(TokenKind::kNumber, what);
    std::uint64_t v = 0;
    auto [p, ec] = std::from_chars(t.text.data(), t.text.data() + t.text.size(), v);
    if (ec != std::errc() || p != t.text.data() + t.text.size()) Fail(t, what);
    return v;
  }
  std::uint32_t MessageId() {
    const Token& t = lex_.Peek();
    const std::uint64_t v = Unsigned("a message ID");
    if (v > 0xFFFFFFFFu) FailAt(t.line, t.column, "message ID above 32 bits");
    return static_cast<std::uint32_t>(v);
  }

  void SkipToSemicolon() {
    for (;;) {
      Token t = lex_.Next();
      if (t.kind == TokenKind::kEnd) return;
      if (t.kind == TokenKind::kPunct && t.text[0] == ';') return;
    }
  }

  void Statement() {
    Token kw = lex_.Next();
    if (kw.kind != TokenKind::kIdentifier) Fail(kw, "a DBC keyword");
    const std::string_view k = kw.text;
    if (k == "VERSION") {
      dbc_.version = Unescape(Expect(TokenKind::kString, "a version string").text);
    } else if (k == "NS_") {
      ExpectPunct(':');
      // The new-symbols list: identifiers until the next section.
      while (lex_.Peek().kind == TokenKind::kIdentifier && lex_.Peek().text != "BS_" &&
             lex_.Peek().text != "BU_" && lex_.Peek().text != "BO_") {
        lex_.Next();
      }
    } else if (k == "BS_") {
      ExpectPunct(':');
      // Optional "baudrate : BTR1 , BTR2" (obsolete).
      if (lex_.Peek().kind == TokenKind::kNumber) {
        Number("a baud rate");
        ExpectPunct(':');
        Number("BTR1");
        ExpectPunct(',');
        Number("BTR2");
      }
    } else if (k == "BU_") {
      ExpectPunct(':');
      while (lex_.Peek().kind == TokenKind::kIdentifier && !IsKeyword(lex_.Peek().text)) {
        dbc_.nodes.emplace_back(lex_.Next().text);
      }
    } else if (k == "VAL_TABLE_") {
      const std::string name(Expect(TokenKind::kIdentifier, "a value table name").text);
      dbc_.value_tables[name] = ValueDescriptions();
    } else if (k == "BO_") {
      Message(kw);
    } else if (k == "SG_") {
      Signal(kw);
    } else if (k == "CM_") {
      Comment();
    } else if (k == "BA_DEF_") {
      AttributeDefinition();
    } else if (k == "BA_DEF_DEF_") {
      AttributeDefault(kw);
    } else if (k == "BA_") {
      Attribute(kw);
    } else if (k == "VAL_") {
      Values(kw);
    } else if (k == "SIG_VALTYPE_") {
      SignalValueType_(kw);
    } else if (k == "SG_MUL_VAL_") {
      MultiplexValues(kw);
    } else {
      // A section this reader does not use (EV_, SIG_GROUP_, BO_TX_BU_, BA_DEF_REL_, ...).
      SkipToSemicolon();
    }
  }

  void Message(const Token& kw) {
    message_raw_id_.reset();
    const std::uint32_t raw_id = MessageId();
    message_raw_id_ = raw_id;
    const Token name = Expect(TokenKind::kIdentifier, "a message name");
    ExpectPunct(':');
    const Token size_tok = lex_.Peek();
    const std::uint64_t size = Unsigned("the message length in bytes");
    const Token tx = Expect(TokenKind::kIdentifier, "the transmitting node");
    current_message_ = -1;
    if (raw_id == kIndependentSignalsId || name.text == "VECTOR__INDEPENDENT_SIG_MSG") {
      skipping_signals_ = true;  // signals of the pseudo-message are not on any bus
      return;
    }
    skipping_signals_ = false;
    if (size > 64) FailAt(size_tok.line, size_tok.column, "message length above 64 bytes");
    DbcMessage m;
    m.extended = (raw_id & kExtendedFlag) != 0;
    m.id = raw_id & ~kExtendedFlag;
    if (m.extended && m.id > 0x1FFFFFFFu) {
      // Only bit 31 is a flag; a raw ID with bit 30 (or 29) set as well names no CAN frame.
      FailAt(kw.line, kw.column,
             fmt::format("extended message ID {:#x} above 29 bits (raw {})", m.id, raw_id));
    }
    if (!m.extended && m.id > 0x7FFu) {
      if (m.id > 0x1FFFFFFFu) {
        FailAt(kw.line, kw.column, fmt::format("message ID {:#x} above 29 bits", m.id));
      }
      // Some writers omit bit 31; such an ID can only be a 29-bit one.
      Problem(kw.line, kw.column,
              fmt::format("message ID {:#x} above 11 bits without bit 31 set: read as "
                          "a 29-bit ID",
                          m.id));
      m.extended = true;
    }
    if (dbc_.FindMessage(m.id, m.extended) != nullptr) {
      FailAt(kw.line, kw.column, fmt::format("duplicate message ID {:#x}", m.id));
    }
    m.name = std::string(name.text);
    m.size_bytes = static_cast<std::uint32_t>(size);
    m.transmitter = std::string(tx.text);
    m.line = kw.line;
    dbc_.messages.push_back(std::move(m));
    current_message_ = static_cast<int>(dbc_.messages.size()) - 1;
  }

  void Signal(const Token& kw) {
    if (current_message_ < 0 && !skipping_signals_) Fail(kw, "BO_ before SG_");
    DbcSignal s;
    s.line = kw.line;
    s.column = kw.column;
    const Token name = Expect(TokenKind::kIdentifier, "a signal name");
    s.name = std::string(name.text);
    std::optional<std::uint64_t> mux_value;
    // Multiplexer indicator: M, mN, or mNM.
    if (lex_.Peek().kind == TokenKind::kIdentifier) {
      const Token ind = lex_.Next();
      std::string_view v = ind.text;
      if (v == "M") {
        s.is_multiplexer = true;
      } else if (v == "m") {
        // vw_pq.dbc (opendbc) writes a lone lower-case "m" for the multiplexer.
        s.is_multiplexer = true;
        Problem(ind.line, ind.column,
                fmt::format("multiplexer indicator 'm' of {} read as 'M'", s.name));
      } else if (v.size() >= 2 && v[0] == 'm' && IsDigit(v[1])) {
        v.remove_prefix(1);
        if (v.back() == 'M') {
          s.is_multiplexer = true;
          v.remove_suffix(1);
        }
        std::uint64_t n = 0;
        auto [p, ec] = std::from_chars(v.data(), v.data() + v.size(), n);
        if (ec != std::errc() || p != v.data() + v.size())
          Fail(ind, "a multiplexer indicator (M, mN or mNM)");
        mux_value = n;
      } else {
        Fail(ind, "a multiplexer indicator (M, mN or mNM) or ':'");
      }
    }
    ExpectPunct(':');
    const Token start_tok = lex_.Peek();
    const std::uint64_t start = Unsigned("the start bit");
    ExpectPunct('|');
    const Token len_tok = lex_.Peek();
    const std::uint64_t length = Unsigned("the signal length in bits");
    ExpectPunct('@');
    // "@1+" lexes as '@', number "1", punct '+'; "@0-" similarly.
    const Token order = lex_.Next();
    if (order.kind != TokenKind::kNumber || (order.text != "0" && order.text != "1")) {
      Fail(order, "byte order 0 (Motorola) or 1 (Intel) after '@'");
    }
    s.byte_order = order.text == "1" ? ByteOrder::kLittleEndian : ByteOrder::kBigEndian;
    const Token sign = lex_.Next();
    if (sign.kind != TokenKind::kPunct || (sign.text[0] != '+' && sign.text[0] != '-')) {
      Fail(sign, "'+' (unsigned) or '-' (signed)");
    }
    s.is_signed = sign.text[0] == '-';
    ExpectPunct('(');
    s.factor = Number("the factor");
    ExpectPunct(',');
    s.offset = Number("the offset");
    ExpectPunct(')');
    ExpectPunct('[');
    s.minimum = Number("the minimum");
    ExpectPunct('|');
    s.maximum = Number("the maximum");
    ExpectPunct(']');
    s.unit = Unescape(Expect(TokenKind::kString, "the unit string").text);
    // Receivers: comma-separated node names on the same line (some writers omit the commas).
    while (lex_.Peek().kind == TokenKind::kIdentifier && lex_.Peek().line == kw.line &&
           !IsKeyword(lex_.Peek().text)) {
      s.receivers.emplace_back(lex_.Next().text);
      AcceptPunct(',');
    }
    if (length == 0 || length > 64) {
      FailAt(len_tok.line, len_tok.column, "signal length must be 1 to 64 bits");
    }
    if (start >= 512) FailAt(start_tok.line, start_tok.column, "start bit beyond 64 bytes");
    s.start_bit = static_cast<std::uint32_t>(start);
    s.length_bits = static_cast<std::uint32_t>(length);
    if (mux_value) s.multiplexer_ranges.push_back({*mux_value, *mux_value});
    if (skipping_signals_) return;
    DbcMessage& m = dbc_.messages[static_cast<std::size_t>(current_message_)];
    if (m.FindSignal(s.name) >= 0) {
      FailAt(name.line, name.column,
             fmt::format("duplicate signal {} in message {}", s.name, m.name));
    }
    simple_mux_.resize(dbc_.messages.size());
    simple_mux_[static_cast<std::size_t>(current_message_)].push_back(mux_value.has_value());
    m.signals.push_back(std::move(s));
  }

  std::map<std::int64_t, std::string> ValueDescriptions() {
    std::map<std::int64_t, std::string> out;
    while (!AcceptPunct(';')) {
      const Token& t = lex_.Peek();
      if ((t.kind == TokenKind::kIdentifier && IsKeyword(t.text)) || t.kind == TokenKind::kEnd) {
        Problem(t.line, t.column,
                t.kind == TokenKind::kEnd ? "missing ';' at the end of the file"
                                          : "missing ';' before this line");
        break;
      }
      if (t.kind != TokenKind::kNumber) Fail(t, "a raw value or ';'");
      // Values may be written as "1" or "1.0"; some tools write huge unsigned values.
      const Token num = lex_.Next();
      double v = 0.0;
      std::string_view sv = num.text;
      if (!sv.empty() && sv[0] == '+') sv.remove_prefix(1);
      auto [p, ec] = std::from_chars(sv.data(), sv.data() + sv.size(), v);
      if (ec != std::errc() || p != sv.data() + sv.size()) Fail(num, "a raw value");
      // A raw value is a 64-bit integer at most; converting a double outside that range to one
      // is undefined behaviour.
      if (!(v >= -9223372036854775808.0 && v < 9223372036854775808.0)) {
        Fail(num, "a raw value within the 64-bit integer range");
      }
      const std::string label =
          Unescape(Expect(TokenKind::kString, "a value description string").text);
      out[static_cast<std::int64_t>(v)] = label;
    }
    return out;
  }

  DbcMessage* MessageByRawId(std::uint32_t raw_id) {
    const bool ext = (raw_id & kExtendedFlag) != 0;
    return const_cast<DbcMessage*>(dbc_.FindMessage(raw_id & ~kExtendedFlag, ext));
  }

  DbcSignal* SignalByRawId(std::uint32_t raw_id, std::string_view name, int line, int column,
                           const char* where) {
    DbcMessage* m = MessageByRawId(raw_id);
    if (m == nullptr) {
      if (!Ignored(raw_id)) {
        Problem(line, column, fmt::format("{} refers to unknown message ID {}", where, raw_id));
      }
      return nullptr;
    }
    const int i = m->FindSignal(name);
    if (i < 0) {
      Problem(line, column,
              fmt::format("{} refers to unknown signal {} in message {}", where, name, m->name));
      return nullptr;
    }
    return &m->signals[static_cast<std::size_t>(i)];
  }

  void Comment() {
    const Token& t = lex_.Peek();
    if (t.kind == TokenKind::kString) {
      dbc_.comment = Unescape(lex_.Next().text);
      ExpectPunct(';');
      return;
    }
    const Token obj = Expect(TokenKind::kIdentifier, "BU_, BO_, SG_, EV_ or a comment string");
    // The comment is applied once its ';' is read: a statement skipped as malformed leaves nothing.
    if (obj.text == "BO_") {
      const std::uint32_t id = MessageId();
      const std::string text = Unescape(Expect(TokenKind::kString, "a comment string").text);
      ExpectPunct(';');
      if (DbcMessage* m = MessageByRawId(id)) {
        m->comment = text;
      } else if (!Ignored(id)) {
        Problem(obj.line, obj.column, fmt::format("CM_ refers to unknown message ID {}", id));
      }
    } else if (obj.text == "SG_") {
      const std::uint32_t id = MessageId();
      const std::string sig(Expect(TokenKind::kIdentifier, "a signal name").text);
      const std::string text = Unescape(Expect(TokenKind::kString, "a comment string").text);
      ExpectPunct(';');
      if (DbcSignal* s = SignalByRawId(id, sig, obj.line, obj.column, "CM_")) s->comment = text;
    } else if (obj.text == "BU_") {
      const std::string node(Expect(TokenKind::kIdentifier, "a node name").text);
      const std::string text = Unescape(Expect(TokenKind::kString, "a comment string").text);
      ExpectPunct(';');
      dbc_.node_comments[node] = text;
    } else if (obj.text == "EV_") {
      Expect(TokenKind::kIdentifier, "a name");
      Expect(TokenKind::kString, "a comment string");
      ExpectPunct(';');
    } else {
      Fail(obj, "BU_, BO_, SG_, EV_ or a comment string");
    }
  }

  DbcAttributeValue AttributeValueToken(const char* what) {
    const Token& t = lex_.Peek();
    if (t.kind == TokenKind::kString) return Unescape(lex_.Next().text);
    return Number(what);
  }

  void AttributeDefinition() {
    DbcAttributeDefinition d;
    d.object = DbcAttributeDefinition::Object::kNetwork;
    if (lex_.Peek().kind == TokenKind::kIdentifier) {
      const Token obj = lex_.Next();
      if (obj.text == "BU_")
        d.object = DbcAttributeDefinition::Object::kNode;
      else if (obj.text == "BO_")
        d.object = DbcAttributeDefinition::Object::kMessage;
      else if (obj.text == "SG_")
        d.object = DbcAttributeDefinition::Object::kSignal;
      else if (obj.text == "EV_")
        d.object = DbcAttributeDefinition::Object::kEnvironment;
      else
        Fail(obj, "BU_, BO_, SG_, EV_ or the attribute name");
    }
    d.name = Unescape(Expect(TokenKind::kString, "the attribute name").text);
    const Token type = Expect(TokenKind::kIdentifier, "INT, HEX, FLOAT, STRING or ENUM");
    if (type.text == "INT" || type.text == "HEX" || type.text == "FLOAT") {
      d.type = type.text == "INT"   ? DbcAttributeDefinition::Type::kInt
               : type.text == "HEX" ? DbcAttributeDefinition::Type::kHex
                                    : DbcAttributeDefinition::Type::kFloat;
      d.minimum = Number("the attribute minimum");
      d.maximum = Number("the attribute maximum");
    } else if (type.text == "STRING") {
      d.type = DbcAttributeDefinition::Type::kString;
    } else if (type.text == "ENUM") {
      d.type = DbcAttributeDefinition::Type::kEnum;
      while (lex_.Peek().kind == TokenKind::kString) {
        d.enum_values.push_back(Unescape(lex_.Next().text));
        if (!AcceptPunct(',')) break;
      }
    } else {
      Fail(type, "INT, HEX, FLOAT, STRING or ENUM");
    }
    ExpectPunct(';');
    dbc_.attribute_definitions.push_back(std::move(d));
  }

  DbcAttributeDefinition* Definition(std::string_view name) {
    for (auto& d : dbc_.attribute_definitions) {
      if (d.name == name) return &d;
    }
    return nullptr;
  }

  void AttributeDefault(const Token& kw) {
    const Token name = Expect(TokenKind::kString, "the attribute name");
    DbcAttributeValue v = AttributeValueToken("the default value");
    ExpectPunct(';');
    if (DbcAttributeDefinition* d = Definition(Unescape(name.text))) {
      d->default_value = std::move(v);
    } else {
      Problem(kw.line, kw.column,
              fmt::format("BA_DEF_DEF_ for undeclared attribute {}", name.text));
    }
  }

  void Attribute(const Token& kw) {
    PendingAttribute a;
    a.line = kw.line;
    a.column = kw.column;
    a.name = Unescape(Expect(TokenKind::kString, "the attribute name").text);
    a.object = DbcAttributeDefinition::Object::kNetwork;
    if (lex_.Peek().kind == TokenKind::kIdentifier) {
      const Token obj = lex_.Next();
      if (obj.text == "BU_") {
        a.object = DbcAttributeDefinition::Object::kNode;
        a.node = std::string(Expect(TokenKind::kIdentifier, "a node name").text);
      } else if (obj.text == "BO_") {
        a.object = DbcAttributeDefinition::Object::kMessage;
        a.message_id_raw = MessageId();
      } else if (obj.text == "SG_") {
        a.object = DbcAttributeDefinition::Object::kSignal;
        a.message_id_raw = MessageId();
        a.signal = std::string(Expect(TokenKind::kIdentifier, "a signal name").text);
      } else if (obj.text == "EV_") {
        a.object = DbcAttributeDefinition::Object::kEnvironment;
        a.node = std::string(Expect(TokenKind::kIdentifier, "an environment variable").text);
      } else {
        Fail(obj, "BU_, BO_, SG_, EV_ or a value");
      }
    }
    a.value = AttributeValueToken("the attribute value");
    ExpectPunct(';');
    attributes_.push_back(std::move(a));
  }

  void Values(const Token& kw) {
    if (lex_.Peek().kind == TokenKind::kIdentifier) {  // values of an environment variable
      SkipToSemicolon();
      return;
    }
    const std::uint32_t id = MessageId();
    const std::string sig(Expect(TokenKind::kIdentifier, "a signal name").text);
    auto values = ValueDescriptions();
    if (DbcSignal* s = SignalByRawId(id, sig, kw.line, kw.column, "VAL_"))
      s->value_descriptions = std::move(values);
  }

  void SignalValueType_(const Token& kw) {
    const std::uint32_t id = MessageId();
    const std::string sig(Expect(TokenKind::kIdentifier, "a signal name").text);
    AcceptPunct(':');
    const Token t = lex_.Peek();
    const std::uint64_t type = Unsigned("0 (integer), 1 (float) or 2 (double)");
    ExpectPunct(';');
    if (type > 2) Fail(t, "0 (integer), 1 (float) or 2 (double)");
    DbcSignal* s = SignalByRawId(id, sig, kw.line, kw.column, "SIG_VALTYPE_");
    if (s == nullptr) return;
    const std::uint32_t need = type == 1 ? 32 : type == 2 ? 64 : s->length_bits;
    if (s->length_bits != need) {
      FailAt(t.line, t.column,
             fmt::format("signal {} is {} bits long; an IEEE {} needs {}", sig, s->length_bits,
                         type == 1 ? "float" : "double", need));
    }
    s->value_type = type == 0   ? SignalValueType::kInteger
                    : type == 1 ? SignalValueType::kFloat32
                                : SignalValueType::kFloat64;
  }

  void MultiplexValues(const Token& kw) {
    PendingMuxValues p;
    p.line = kw.line;
    p.column = kw.column;
    p.message_id_raw = MessageId();
    p.signal = std::string(Expect(TokenKind::kIdentifier, "the multiplexed signal").text);
    p.switch_name = std::string(Expect(TokenKind::kIdentifier, "the multiplexer switch").text);
    do {
      const std::uint64_t low = Unsigned("the low end of a range");
      // "3-5" lexes as "3" and "-5".
      const Token high = lex_.Next();
      std::string_view h = high.text;
      if (high.kind == TokenKind::kPunct && h == "-") {
        p.ranges.push_back({low, Unsigned("the high end of a range")});
        continue;
      }
      if (high.kind != TokenKind::kNumber || h.empty() || h[0] != '-')
        Fail(high, "'-' and the high end of a range");
      h.remove_prefix(1);
      std::uint64_t hv = 0;
      auto [q, ec] = std::from_chars(h.data(), h.data() + h.size(), hv);
      if (ec != std::errc() || q != h.data() + h.size()) Fail(high, "the high end of a range");
      p.ranges.push_back({low, hv});
    } while (AcceptPunct(','));
    ExpectPunct(';');
    mux_values_.push_back(std::move(p));
  }

  /// Work that needs the whole file: attributes, multiplexer links, bit ranges.
  void Resolve() {
    for (auto& a : attributes_) ApplyAttribute(a);
    for (auto& m : dbc_.messages) {
      if (!m.attributes.contains("GenMsgCycleTime")) {
        if (const auto* d = Definition("GenMsgCycleTime"); d && d->default_value) {
          if (const double* v = std::get_if<double>(&*d->default_value)) m.cycle_time_ms = *v;
        }
      }
    }
    // Extended multiplexing: SG_MUL_VAL_ names the switch and the ranges.
    std::set<std::pair<int, int>> explicit_mux;
    for (auto& p : mux_values_) {
      DbcMessage* m = MessageByRawId(p.message_id_raw);
      if (m == nullptr) {
        if (!Ignored(p.message_id_raw)) {
          Problem(p.line, p.column,
                  fmt::format("SG_MUL_VAL_ refers to unknown message ID {}", p.message_id_raw));
        }
        continue;
      }
      const int i = m->FindSignal(p.signal);
      const int sw = m->FindSignal(p.switch_name);
      if (i < 0 || sw < 0) {
        FailAt(p.line, p.column,
               fmt::format("SG_MUL_VAL_ names unknown signal {} in message {}",
                           i < 0 ? p.signal : p.switch_name, m->name));
      }
      if (!m->signals[static_cast<std::size_t>(sw)].is_multiplexer) {
        FailAt(p.line, p.column,
               fmt::format("SG_MUL_VAL_ switch {} is not a multiplexer (M or mNM)", p.switch_name));
      }
      DbcSignal& s = m->signals[static_cast<std::size_t>(i)];
      s.multiplexer_switch = p.switch_name;
      s.multiplexer_ranges = p.ranges;
      explicit_mux.insert({static_cast<int>(m - dbc_.messages.data()), i});
    }
    simple_mux_.resize(dbc_.messages.size());
    for (std::size_t mi = 0; mi < dbc_.messages.size(); ++mi) {
      DbcMessage& m = dbc_.messages[mi];
      const std::vector<bool>& muxed = simple_mux_[mi];
      // Simple multiplexing: the message's one multiplexer that is not itself multiplexed.
      int top = -1;
      int top_count = 0;
      for (std::size_t j = 0; j < m.signals.size(); ++j) {
        if (m.signals[j].is_multiplexer && !muxed[j]) {
          top = static_cast<int>(j);
          ++top_count;
        }
      }
      for (std::size_t si = 0; si < m.signals.size(); ++si) {
        if (!muxed[si] || explicit_mux.contains({static_cast<int>(mi), static_cast<int>(si)}))
          continue;
        DbcSignal& s = m.signals[si];
        if (top_count != 1) {
          FailAt(s.line, 1,
                 fmt::format("signal {} of {} is multiplexed but the message has {} top-level "
                             "multiplexers and no SG_MUL_VAL_ for it",
                             s.name, m.name, top_count));
        }
        s.multiplexer_switch = m.signals[static_cast<std::size_t>(top)].name;
      }
    }
    for (auto& m : dbc_.messages) CheckMessage(m);
    ApplyLongNames();
    std::stable_sort(dbc_.problems.begin(), dbc_.problems.end(),
                     [](const DbcProblem& a, const DbcProblem& b) { return a.line < b.line; });
  }

  void ApplyAttribute(PendingAttribute& a) {
    const DbcAttributeDefinition* d = Definition(a.name);
    if (d == nullptr) {
      Problem(a.line, a.column, fmt::format("BA_ for undeclared attribute {}", a.name));
    } else if (d->type == DbcAttributeDefinition::Type::kEnum) {
      // BA_ writes an enum attribute as its index; keep the label.
      if (const double* idx = std::get_if<double>(&a.value)) {
        if (*idx >= 0 && *idx < static_cast<double>(d->enum_values.size())) {
          a.value = d->enum_values[static_cast<std::size_t>(*idx)];
        }
      }
    }
    switch (a.object) {
      case DbcAttributeDefinition::Object::kNetwork:
        dbc_.network_attributes[a.name] = a.value;
        break;
      case DbcAttributeDefinition::Object::kMessage: {
        DbcMessage* m = MessageByRawId(a.message_id_raw);
        if (m == nullptr) {
          if (!Ignored(a.message_id_raw)) {
            Problem(a.line, a.column,
                    fmt::format("BA_ refers to unknown message ID {}", a.message_id_raw));
          }
          break;
        }
        m->attributes[a.name] = a.value;
        if (a.name == "GenMsgCycleTime") {
          if (const double* v = std::get_if<double>(&a.value)) m->cycle_time_ms = *v;
        }
        break;
      }
      case DbcAttributeDefinition::Object::kSignal: {
        DbcSignal* s = SignalByRawId(a.message_id_raw, a.signal, a.line, a.column, "BA_");
        if (s == nullptr) break;
        s->attributes[a.name] = a.value;
        if (a.name == "GenSigSNA") {
          // Real files declare it as a STRING ("FFFh"); only an integer raw value is usable.
          const double* v = std::get_if<double>(&a.value);
          if (v == nullptr || *v != std::floor(*v) ||
              !(*v >= -9223372036854775808.0 && *v < 9223372036854775808.0)) {
            Problem(a.line, a.column,
                    fmt::format("GenSigSNA of signal {} is not an integer raw value within the "
                                "64-bit range; ignored",
                                a.signal));
            break;
          }
          s->not_available_raw = static_cast<std::int64_t>(*v);
        }
        break;
      }
      case DbcAttributeDefinition::Object::kNode:
        dbc_.node_attributes[a.node][a.name] = a.value;
        break;
      default:
        break;  // environment variables are skipped, and their attributes with them
    }
  }

  /// The long name in `attributes` under `key` (removed from them), or "" when none is given.
  static std::string TakeLongName(DbcAttributes& attributes, std::string_view key) {
    const auto it = attributes.find(key);
    if (it == attributes.end()) return "";
    const std::string* text = std::get_if<std::string>(&it->second);
    std::string name = text ? *text : "";
    attributes.erase(it);
    return name;
  }

  /// Long names (the header's "Long names"), once every statement has been resolved by the
  /// short names. A long name that would repeat a name already taken keeps the short one.
  void ApplyLongNames() {
    std::map<std::string, std::string, std::less<>> node_names;
    for (auto& [node, attributes] : dbc_.node_attributes) {
      const std::string long_name = TakeLongName(attributes, "SystemNodeLongSymbol");
      if (!long_name.empty()) node_names[node] = long_name;
    }
    auto node_name = [&](std::string& name) {
      if (const auto it = node_names.find(name); it != node_names.end()) name = it->second;
    };
    for (auto& n : dbc_.nodes) node_name(n);
    RenameKeys(dbc_.node_attributes, node_names);
    RenameKeys(dbc_.node_comments, node_names);
    std::set<std::string, std::less<>> message_names;
    for (const auto& m : dbc_.messages) message_names.insert(m.name);
    for (auto& m : dbc_.messages) {
      node_name(m.transmitter);
      const std::string long_name = TakeLongName(m.attributes, "SystemMessageLongSymbol");
      if (!long_name.empty() && long_name != m.name) {
        if (message_names.contains(long_name)) {
          Problem(m.line, 1,
                  fmt::format("SystemMessageLongSymbol \"{}\" of message {} is the "
                              "name of another message; the short name is kept",
                              long_name, m.name));
        } else {
          message_names.insert(long_name);
          m.name = long_name;
        }
      }
      std::map<std::string, std::string, std::less<>> signal_names;
      std::set<std::string, std::less<>> taken;
      for (const auto& s : m.signals) taken.insert(s.name);
      for (auto& s : m.signals) {
        for (auto& r : s.receivers) node_name(r);
        const std::string long_signal = TakeLongName(s.attributes, "SystemSignalLongSymbol");
        if (long_signal.empty() || long_signal == s.name) continue;
        if (taken.contains(long_signal)) {
          Problem(s.line, s.column,
                  fmt::format("SystemSignalLongSymbol \"{}\" of signal {} is the name of "
                              "another signal of {}; the short name is kept",
                              long_signal, s.name, m.name));
          continue;
        }
        taken.insert(long_signal);
        signal_names[s.name] = long_signal;
        s.name = long_signal;
      }
      for (auto& s : m.signals) {
        if (const auto it = signal_names.find(s.multiplexer_switch); it != signal_names.end())
          s.multiplexer_switch = it->second;
      }
    }
  }

  template <typename Map>
  static void RenameKeys(Map& map, const std::map<std::string, std::string, std::less<>>& names) {
    for (const auto& [from, to] : names) {
      auto node = map.extract(from);
      if (node.empty()) continue;
      node.key() = to;
      map.insert(std::move(node));
    }
  }

  void CheckMessage(DbcMessage& m) {
    for (auto& s : m.signals) {
      const std::uint32_t need = SignalEndByte(s);
      if (need > 64) {
        FailAt(s.line, 1,
               fmt::format("signal {} of {} reaches byte {}, beyond 64 bytes", s.name, m.name,
                           need - 1));
      }
      if (need > m.size_bytes) {
        Problem(s.line, s.column,
                fmt::format("signal {} of {} reaches byte {} but the message is {} bytes: it "
                            "decodes as not available",
                            s.name, m.name, need - 1, m.size_bytes));
      }
      if (s.not_available_raw) {
        const std::int64_t v = *s.not_available_raw;
        const bool fits = s.length_bits >= 63 ||
                          (s.is_signed ? (v >= -(std::int64_t{1} << (s.length_bits - 1)) &&
                                          v < (std::int64_t{1} << (s.length_bits - 1)))
                                       : (v >= 0 && v < (std::int64_t{1} << s.length_bits)));
        if (!fits) {
          Problem(s.line, s.column,
                  fmt::format("GenSigSNA {} of signal {} does not fit in {} bits; ignored", v,
                              s.name, s.length_bits));
          s.not_available_raw.reset();
        }
      }
    }
    // Multiplexer chains must end: follow each signal's switch at most signals.size() steps.
    for (const auto& s : m.signals) {
      const DbcSignal* cur = &s;
      for (std::size_t steps = 0; !cur->multiplexer_switch.empty(); ++steps) {
        if (steps > m.signals.size()) {
          FailAt(s.line, 1,
                 fmt::format("multiplexer cycle through signal {} of {}", s.name, m.name));
        }
        cur = &m.signals[static_cast<std::size_t>(m.FindSignal(cur->multiplexer_switch))];
      }
    }
  }

  Lexer lex_;
  Dbc dbc_;
  int current_message_ = -1;
  bool skipping_signals_ = false;
  /// Per message, per signal: had an `mN` indicator (multiplexed by the message's multiplexer).
  std::vector<std::vector<bool>> simple_mux_;
  std::vector<PendingMuxValues> mux_values_;
  std::vector<PendingAttribute> attributes_;
  /// Raw ID of the BO_ being read (set before it is checked), and those of skipped messages.
  std::optional<std::uint32_t> message_raw_id_;
  std::set<std::uint32_t> skipped_ids_;
};

}  // namespace

Dbc ParseDbc(std::string_view text, std::string_view file_name) {
  return Parser(text, file_name).Parse();
}

}  // namespace pumptherm::protocol
