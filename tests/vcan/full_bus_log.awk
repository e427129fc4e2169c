# A candump log at the frame rate of a fully loaded 1 Mbit/s CAN bus, for vcan test
# daemon_full_bus: the lines of interface `from` (default can0) of the plant's fleet32 recording
# (16 pumps: 3360 frames/s), renamed `to` (default vcan0), plus filler frames the gateway does not
# know (IDs 0x050-0x05F, 8 bytes: received and counted as unknown IDs) spread evenly so that the
# whole log carries `rate` frames per second (default 9000: 1e6 bit/s / 111 bit, an 8-byte
# standard frame without stuffing bits, interframe space included; the most a 1 Mbit/s bus
# carries). Times are counted in integer microseconds from the first frame (awk's doubles would
# round 16-digit timestamps) and written from t = 0.
#   awk [-v rate=9000] [-v from=can0] [-v to=vcan0] -f full_bus_log.awk LOG LOG
# (the log twice: the first pass counts the frames and the duration).
function us(field,    s, dot) {
  s = substr(field, 2, length(field) - 2)
  dot = index(s, ".")
  return (substr(s, 1, dot - 1) - sec0) * 1000000 + substr(s, dot + 1)
}
function stamp(t) { return sprintf("(%010d.%06d)", int(t / 1000000), t % 1000000) }
BEGIN {
  if (rate == "") rate = 9000
  if (from == "") from = "can0"
  if (to == "") to = "vcan0"
}
FNR == 1 && NR == 1 { s = substr($1, 2); sec0 = substr(s, 1, index(s, ".") - 1) + 0 }
FNR == NR { if ($2 == from) { n++; t = us($1); if (n == 1) first = t; last = t }; next }
FNR == 1 {
  span = last - first + 1000000 / rate                   # us
  nfill = int(rate * span / 1000000 + 0.5) - n
  if (nfill < 0) { print "full_bus_log.awk: the recording alone exceeds the rate" > "/dev/stderr"; exit 1 }
  k = 0
}
$2 == from {
  t = us($1)
  while (k < nfill && first + int(k * span / nfill) < t) {
    print stamp(first + int(k * span / nfill) - first), to, sprintf("%03X#%016X", 80 + k % 16, k)
    k++
  }
  print stamp(t - first), to, $3
}
END {
  while (k < nfill) { print stamp(first + int(k * span / nfill) - first), to, sprintf("%03X#%016X", 80 + k % 16, k); k++ }
}
