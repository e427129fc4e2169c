#include "daemon/offline.hpp"

#include <fmt/format.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <iterator>
#include <lcm/lcm-cpp.hpp>
#include <stdexcept>
#include <string_view>
#include <system_error>
#include <thread>
#include <vector>

#include "daemon/gateway_detail.hpp"
#include "daemon/log.hpp"
#include "daemon/published_fields.hpp"
#include "protocol/candump_log.hpp"

namespace pumptherm::daemon {
namespace {

/// An output file ("-": standard output, left open).
struct File {
  std::FILE* f = nullptr;
  std::string path;
  File(const std::string& p, const char* mode) : path(p) {
    if (p.empty()) return;
    f = p == "-" ? stdout : std::fopen(p.c_str(), mode);
    if (!f) throw std::runtime_error(fmt::format("{}: cannot create: {}", p, std::strerror(errno)));
  }
  ~File() {
    if (f && f != stdout) std::fclose(f);
  }
  File(const File&) = delete;
  File& operator=(const File&) = delete;
  void Close() {
    if (!f) return;
    const bool bad = std::fflush(f) != 0 || std::ferror(f);
    if (f != stdout) std::fclose(f);
    f = nullptr;
    if (bad) throw std::runtime_error(fmt::format("{}: write error", path));
  }
};

/// Frames to a candump log, LCM messages to an LCM log.
class LogSink : public OutputSink {
 public:
  LogSink(const OfflineOptions& o, const Gateway& g)
      : frames_(o.output_log, "w"), gateway_(g), publish_(o.lcm_publish) {
    if (!o.lcm_log.empty()) {
      lcm_ = std::make_unique<lcm::LogFile>(o.lcm_log, "w");
      if (!lcm_->good())
        throw std::runtime_error(fmt::format("{}: cannot create the LCM log", o.lcm_log));
    }
  }
  void SendFrame(std::size_t iface, std::int64_t time_us,
                 const protocol::CanFrame& frame) override {
    ++frames_out;
    if (!frames_.f) return;
    line_.clear();  // keeps its capacity: no allocation per frame
    protocol::AppendCandumpLine(line_, time_us, gateway_.counter().interfaces()[iface].name, frame);
    line_ += '\n';
    std::fwrite(line_.data(), 1, line_.size(), frames_.f);  // errors show at Close (ferror)
  }
  bool PublishLcm(const std::string& channel, std::int64_t time_us,
                  const std::vector<std::uint8_t>& bytes) override {
    ++lcm_out;
    bool sent = true;
    if (publish_ != nullptr)
      sent = publish_->publish(channel, bytes.data(), static_cast<unsigned>(bytes.size())) == 0;
    if (!lcm_) return sent;
    lcm::LogEvent ev;
    ev.eventnum = 0;
    ev.timestamp = time_us;
    ev.channel = channel;
    ev.datalen = static_cast<std::int32_t>(bytes.size());
    ev.data = const_cast<std::uint8_t*>(bytes.data());
    return lcm_->writeEvent(&ev) == 0 && sent;
  }
  void Close() {
    frames_.Close();
    lcm_.reset();
  }
  std::uint64_t frames_out = 0;
  std::uint64_t lcm_out = 0;

 private:
  File frames_;
  const Gateway& gateway_;
  std::string line_;  ///< the line being written, its capacity kept
  std::unique_ptr<lcm::LogFile> lcm_;
  lcm::LCM* publish_;
};

/// One CSV per pump, a row per thermal step.
class CsvSink {
 public:
  CsvSink(const OfflineOptions& o, const Gateway& g) : origin_s_(o.csv_time_origin_s) {
    const std::string& dir = o.csv_dir;
    if (dir.empty() && o.csv_file.empty()) return;
    std::error_code ec;
    if (!dir.empty()) std::filesystem::create_directories(dir, ec);  // like the tools' --out
    if (ec) throw std::system_error(ec, "--csv-dir: cannot create '" + dir + "'");
    for (const auto& p : g.pumps()) {
      files_.push_back(std::make_unique<File>(
          dir.empty() ? o.csv_file : fmt::format("{}/{}.csv", dir, p->config().name), "w"));
      std::string header = "time_s";
      for (const auto& n : p->model().StateNames()) header += fmt::format(",{}_degC,{}_sd_K", n, n);
      header += CsvHeader() + "\n";
      std::fputs(header.c_str(), files_.back()->f);
      last_.push_back(-1);
      if (dir.empty()) break;  // csv_file: the first pump's
    }
  }
  /// `first_us`: the recording's first frame (the default origin's whole second).
  void Write(const Gateway& g, std::int64_t first_us) {
    if (std::isnan(origin_s_)) origin_s_ = std::floor(static_cast<double>(first_us) * 1e-6);
    for (std::size_t i = 0; i < files_.size(); ++i) {
      const PumpSnapshot& s = g.pumps()[i]->snapshot();
      // A row per step with an estimate, or with an alarm before the first estimate (its
      // temperatures NaN): the CSV shows what went out on CAN.
      if (!gateway_detail::AlarmKnown(s) || s.time_us == last_[i]) continue;
      last_[i] = s.time_us;
      row_ = fmt::format("{:.3f}", static_cast<double>(s.time_us) * 1e-6 - origin_s_);
      for (std::size_t k = 0; k < s.node_degC.size(); ++k)
        fmt::format_to(std::back_inserter(row_), ",{:.4f},{:.4f}", s.node_degC[k], s.node_sd_K[k]);
      AppendCsvRow(g.Source(*g.pumps()[i]), row_);
      row_ += '\n';
      std::fputs(row_.c_str(), files_[i]->f);
    }
  }
  void Close() {
    for (auto& f : files_) f->Close();
  }

 private:
  double origin_s_;
  std::string row_;  ///< the row being written, its capacity kept
  std::vector<std::unique_ptr<File>> files_;
  std::vector<std::int64_t> last_;
};

/// The lines of a stream, read in large blocks and split with memchr (no per-line stream
/// calls): the view Next gives stays valid until the next call. A last line without a newline
/// is a line, as std::getline has it.
class LineReader {
 public:
  explicit LineReader(std::istream& in) : in_(in), buffer_(kBlockBytes) {}
  bool Next(std::string_view& line) {
    for (;;) {
      const char* begin = buffer_.data() + pos_;
      if (const void* nl = std::memchr(begin, '\n', end_ - pos_)) {
        const auto len = static_cast<std::size_t>(static_cast<const char*>(nl) - begin);
        line = std::string_view(begin, len);
        pos_ += len + 1;
        return true;
      }
      if (eof_) {
        if (pos_ == end_) return false;
        line = std::string_view(begin, end_ - pos_);
        pos_ = end_;
        return true;
      }
      Refill();
    }
  }

 private:
  static constexpr std::size_t kBlockBytes = 1 << 20;
  /// Moves the unfinished line to the front (growing the buffer if it fills it) and reads on.
  void Refill() {
    std::memmove(buffer_.data(), buffer_.data() + pos_, end_ - pos_);
    end_ -= pos_;
    pos_ = 0;
    if (end_ == buffer_.size()) buffer_.resize(2 * buffer_.size());
    std::streamsize n = 0;
    try {
      n = in_.rdbuf()->sgetn(buffer_.data() + end_,
                             static_cast<std::streamsize>(buffer_.size() - end_));
    } catch (const std::exception&) {
      // libstdc++ throws from the file buffer ("basic_filebuf::xsgetn error reading the file:
      // Is a directory"); errno still says why.
      error_ = std::strerror(errno);
      n = 0;
    }
    if (n <= 0) {
      eof_ = true;
    } else {
      end_ += static_cast<std::size_t>(n);
    }
  }
  std::istream& in_;
  std::vector<char> buffer_;
  std::size_t pos_ = 0, end_ = 0;
  bool eof_ = false;
  std::string error_;

 public:
  /// Why reading stopped before the end ("" at the end of the input).
  const std::string& error() const { return error_; }
};

/// Interface indices by name for the offline loop: every line names an interface, nearly always
/// one of very few, so a name is compared as two words (no string compare per frame) with the
/// ones seen before; a new one is registered with the gateway.
class InterfaceCache {
 public:
  explicit InterfaceCache(Gateway& gateway) : gateway_(gateway) {}
  std::size_t Index(std::string_view name) {
    const Key key = KeyOf(name);
    for (const Entry& e : entries_) {
      if (e.key == key) return e.index;
    }
    entries_.push_back({key, gateway_.Interface(name)});
    return entries_.back().index;
  }

 private:
  struct Key {
    std::uint64_t lo = 0, hi = 0;
    bool operator==(const Key&) const = default;
  };
  struct Entry {
    Key key;
    std::size_t index;
  };
  /// The name's bytes (ParseCandumpLine allows at most 15) and, in the last byte, its length.
  static Key KeyOf(std::string_view name) {
    Key k;
    for (std::size_t i = 0; i < name.size() && i < 15; ++i) {
      const auto c = static_cast<std::uint64_t>(static_cast<unsigned char>(name[i]));
      if (i < 8) {
        k.lo |= c << (8 * i);
      } else {
        k.hi |= c << (8 * (i - 8));
      }
    }
    k.hi |= static_cast<std::uint64_t>(std::min<std::size_t>(name.size(), 255)) << 56;
    return k;
  }
  Gateway& gateway_;
  std::vector<Entry> entries_;
};

}  // namespace

std::int64_t OfflineClock::Now(std::int64_t stamp_us) {
  if (last_stamp_us_ >= 0 && stamp_us < last_stamp_us_ - kClockStepUs) {
    // The recording's clock was stepped back: time holds here and runs on from the new stamps.
    ++steps_back_;
    last_step_back_us_ = last_stamp_us_ - stamp_us;
    offset_us_ = last_now_us_ - stamp_us;
  }
  last_stamp_us_ = stamp_us;
  // Frames a little out of order (another interface, jitter) are taken at the later time.
  last_now_us_ = std::max(stamp_us + offset_us_, last_now_us_);
  return last_now_us_;
}

namespace {

/// The lines of a recording held until its first stamps have said what they count.
struct HeldLine {
  std::uint64_t number;
  std::string text;
};

/// Reads the first kCandumpStampsToClassify stamps (or the whole log, if shorter) into `held`
/// and classifies them.
protocol::CandumpTimeBase ProbeTimeBase(LineReader& reader, std::vector<HeldLine>& held) {
  std::vector<std::int64_t> stamps;
  std::string_view line;
  while (stamps.size() < protocol::kCandumpStampsToClassify && reader.Next(line)) {
    held.push_back({held.size() + 1, std::string(line)});
    const protocol::CandumpParse p = protocol::ParseCandumpLine(line);
    if (p.ok && p.record.has_time) stamps.push_back(p.record.time_us);
  }
  return protocol::ClassifyCandumpStamps(stamps.data(), stamps.size());
}

}  // namespace

OfflineResult RunOffline(std::istream& in, const std::string& source, Gateway& gateway,
                         const OfflineOptions& options) {
  OfflineResult r;
  LogSink sink(options, gateway);
  CsvSink csv(options, gateway);
  LineReader reader(in);
  InterfaceCache interfaces(gateway);
  std::int64_t last_time_us = -1;
  std::int64_t next_table_us = -1;
  OfflineClock clock;
  const bool tty = ::isatty(STDERR_FILENO) == 1;
  const auto wall_start = std::chrono::steady_clock::now();
  std::int64_t log_start_us = -1;
  auto show_table = [&](std::int64_t t_us) {
    const double minutes = static_cast<double>(t_us - log_start_us) * 1e-6 / 60.0;
    std::string text = fmt::format("log time {:6.1f} min\n{}", minutes, gateway.PumpTable());
    if (tty) text = "\x1b[H\x1b[2J" + text;  // redraw in place on a terminal
    std::fputs(text.c_str(), stderr);
    std::fflush(stderr);
  };
  std::vector<std::size_t> heartbeat_interfaces;
  for (const auto& i : gateway.config().interfaces)
    heartbeat_interfaces.push_back(gateway.Interface(i.name));
  std::vector<HeldLine> held;
  r.time_base = ProbeTimeBase(reader, held);
  if (r.time_base != protocol::CandumpTimeBase::kAbsolute) {
    Log(LogLevel::kNotice,
        "{}: the timestamps are {}, not Unix time: read as seconds since the recording's start "
        "(the CSV's time_s, LCM utime and the output log count from 0)",
        source, protocol::CandumpTimeBaseName(r.time_base));
  }
  protocol::CandumpTimeline timeline(r.time_base);
  auto process = [&](std::string_view line) {
    ++r.lines;
    const protocol::CandumpParse p = protocol::ParseCandumpLine(line);
    if (p.skip) return;
    if (!p.ok) {
      if (++r.bad_lines <= options.max_reported) {
        Log(LogLevel::kWarning, "{}:{}:{}: {}; line skipped", source, r.lines, p.column, p.error);
      }
      return;
    }
    if (!p.record.has_time) {
      if (++r.untimed_lines <= options.max_reported) {
        Log(LogLevel::kWarning,
            "{}:{}: no timestamp (candump's screen format without -t a): the pipeline runs on the "
            "receive times; line skipped (record with candump -l, -L or -t a)",
            source, r.lines);
      }
      return;
    }
    const std::size_t iface = interfaces.Index(p.record.interface);
    const std::int64_t now = clock.Now(timeline.TimeUs(p.record.time_us));
    SetLogTime(now);  // offline the pipeline's time is the recording's (Unix time)
    if (clock.steps_back() > r.time_steps_back) {
      r.time_steps_back = clock.steps_back();
      if (r.time_steps_back <= options.max_reported) {
        Log(LogLevel::kWarning,
            "{}:{}: time goes back {:.3f} s (logs concatenated, or the recording host's clock set "
            "back): "
            "the pipeline's time holds here and runs on from the new stamps",
            source, r.lines, static_cast<double>(clock.last_step_back_us()) * 1e-6);
      }
    }
    if (log_start_us < 0) log_start_us = now;
    const protocol::TimedFrame frame{now, p.record.frame};
    if (options.on_frame) options.on_frame(iface, frame, r.lines);
    gateway.OnFrame(iface, frame);
    // Time-driven work only when some is due: a frame that brings nothing due costs nothing
    // here. The CSV rows follow the thermal steps, which happen only in Advance.
    if (now >= gateway.NextDueUs()) {
      gateway.Advance(now, sink);
      csv.Write(gateway, log_start_us);
      if (options.after_advance) options.after_advance(gateway, now);
    }
    // The heartbeat, as live on every configured interface.
    if (now >= gateway.counter().NextHeartbeatUs()) {
      while (const auto beat = gateway.counter().HeartbeatDue(now)) {
        for (const std::size_t i : heartbeat_interfaces) sink.SendFrame(i, now, *beat);
      }
    }
    last_time_us = now;
    ++r.frames;
    if (options.pace > 0.0) {
      const auto due = wall_start + std::chrono::microseconds(static_cast<std::int64_t>(
                                        static_cast<double>(now - log_start_us) / options.pace));
      std::this_thread::sleep_until(due);
    }
    if (options.table) {
      if (next_table_us < 0) next_table_us = now;
      if (now >= next_table_us) {
        show_table(now);
        next_table_us = now + static_cast<std::int64_t>(options.table_period_s * 1e6);
      }
    }
  };
  for (const HeldLine& h : held) process(h.text);
  held.clear();
  std::string_view line;
  while (reader.Next(line)) process(line);
  if (!reader.error().empty())
    throw std::runtime_error(
        fmt::format("{}: cannot read the log after line {}: {}", source, r.lines, reader.error()));
  r.first_us = log_start_us;
  r.last_us = last_time_us;
  if (r.time_steps_back > options.max_reported) {
    Log(LogLevel::kWarning, "{}: time went back {} times in all", source, r.time_steps_back);
  }
  if (r.untimed_lines > options.max_reported) {
    Log(LogLevel::kWarning, "{}: {} more lines without a timestamp skipped", source,
        r.untimed_lines - options.max_reported);
  }
  if (r.bad_lines > options.max_reported) {
    Log(LogLevel::kWarning, "{}: {} more malformed lines skipped", source,
        r.bad_lines - options.max_reported);
  }
  if (options.table && last_time_us >= 0) show_table(last_time_us);
  sink.Close();
  csv.Close();
  r.frames_out = sink.frames_out;
  r.lcm_out = sink.lcm_out;
  return r;
}

std::ifstream OpenLog(const std::string& path) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec))
    throw std::runtime_error(fmt::format("{}: is a directory, not a candump log", path));
  std::ifstream file(path, std::ios::binary);
  if (!file)
    throw std::runtime_error(
        fmt::format("{}: cannot read the log: {}", path, std::strerror(errno)));
  return file;
}

void RequireFrames(const OfflineResult& r, const std::string& source) {
  if (r.frames > 0) return;
  if (r.lines == 0) throw std::runtime_error(fmt::format("{}: empty: no frame to run on", source));
  const std::uint64_t other = r.lines - r.bad_lines - r.untimed_lines;
  throw std::runtime_error(fmt::format(
      "{}: no frame to run on in {} line{}: {} not candump lines, {} without a timestamp, {} "
      "blank or comments (docs/protocol.md, \"candump formats\")",
      source, r.lines, r.lines == 1 ? "" : "s", r.bad_lines, r.untimed_lines, other));
}

}  // namespace pumptherm::daemon
