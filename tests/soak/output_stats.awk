# Streams the gateway's output frames (a candump log: `pumpthermd -r ... --output-log FIFO`) and
# keeps what the soak checks (tests/soak/offline_week.sh), in constant memory per CAN ID and hour:
#   - every change of a pump's GW_ALARM level or reason (0x200 + node; AlarmLevel = bits 0-1 of
#     byte 0, AlarmReason = bits 2-7): lines "A <log time s> <iface> <id> <level> <reason>";
#   - frames per CAN ID per hour of log time, and for the periodic messages (GW_TEMPS_A/B, 1 s;
#     GW_IDENT, 0.1 s; GW_HEALTH, 1 s; GW_NODE_TEMP, 1 s / nodes) the lag of each frame behind its schedule (first frame +
#     k periods), per day: drift would show as growing lags or missing frames;
#   - a line "T <seconds of log time>" every `every` seconds of log time, flushed at once, so that
#     the caller can sample the daemon's memory as the log time passes.
# At the end: "H <iface> <id> <hour> <frames>" per ID and hour (counted from that ID's first
# frame; the last one is partial), "L <iface> <id> <day> <min lag
# us> <max lag us> <frames>" per periodic ID and day, "N <frames> <first time> <last time>".
#
# Usage: awk -v every=600 -v nodes=4 -f output_stats.awk OUTPUT_LOG   (nodes: of the model)
function hexbyte(s,    h) {
  h = "0123456789ABCDEF"
  return (index(h, substr(s, 1, 1)) - 1) * 16 + index(h, substr(s, 2, 1)) - 1
}
BEGIN {
  if (every == "") every = 600
  if (nodes == "") nodes = 1
  n = 0
}
{
  ts = substr($1, 2, length($1) - 2)
  dot = index(ts, ".")
  sec = substr(ts, 1, dot - 1) + 0
  usec = substr(ts, dot + 1) + 0
  if (n == 0) { sec0 = sec; next_t = every }
  n++
  rel = (sec - sec0) + usec / 1e6          # log seconds since the first output
  id = substr($3, 1, 3)
  key = $2 " " id
  if (!(key in kfirst)) kfirst[key] = rel
  hour = int((rel - kfirst[key]) / 3600)  # hours from this ID's first frame
  count[key, hour]++
  if (hour > last_hour) last_hour = hour
  keys[key] = 1
  c = substr(id, 1, 1)
  if (c == "2") {
    b0 = hexbyte(substr($3, 5, 2))
    level = b0 % 4
    reason = int(b0 / 4)
    if (!(key in alarm_state) || alarm_state[key] != b0) {
      printf "A %.6f %s %s %d %d\n", rel, $2, id, level, reason
      alarm_state[key] = b0
    }
  } else {
    period = (c == "4" && substr(id, 2, 1) == "2") ? 0.1 : 1.0   # GW_IDENT 0x42n at 10 Hz
    if (c == "4" && substr(id, 2, 1) == "8") period = 1.0 / nodes  # GW_NODE_TEMP: one node per 1 s / nodes
    if (!(key in first)) { first[key] = rel; per[key] = period }
    k = int((rel - first[key]) / period + 0.5)
    lag = (rel - first[key] - k * period) * 1e6
    day = int(rel / 86400)
    dk = key SUBSEP day
    if (!(dk in lag_n) || lag < lag_min[dk]) lag_min[dk] = lag
    if (!(dk in lag_n) || lag > lag_max[dk]) lag_max[dk] = lag
    lag_n[dk]++
    if (day > last_day) last_day = day
  }
  if (rel >= next_t) {
    printf "T %d\n", next_t
    fflush()
    next_t += every
  }
  last_rel = rel
}
END {
  for (key in keys) {
    for (h = 0; h <= last_hour; h++) printf "H %s %d %d\n", key, h, count[key, h] + 0
    if (substr(key, length(key) - 2, 1) != "2") {
      for (d = 0; d <= last_day; d++) {
        dk = key SUBSEP d
        if (dk in lag_n) printf "L %s %d %.1f %.1f %d\n", key, d, lag_min[dk], lag_max[dk], lag_n[dk]
      }
    }
  }
  printf "N %d %d %.6f\n", n, sec0, last_rel
}
