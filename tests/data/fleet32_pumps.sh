#!/bin/sh
# Prints the [[can]] and [[pump]] sections of a pumpthermd configuration for the plant's fleet32
# recordings (tools/plant/scenarios/fleet32.toml, fleet32-week.toml): a00..a15 on can0 and
# b00..b15 on can1, node IDs 0..15, the plant's motor and thermal model, and its frame RTD's
# first-order lag (the plant's default, 30 s: an estimate that does not model it runs that far
# behind a rising frame, and a warning on the estimate that late). Used by the soak
# (tests/soak/offline_week.sh) and the throughput benchmark (tests/bench/offline_throughput.sh),
# which add their own [gateway] and [alarms] sections before it.
set -eu
printf '[[can]]\ninterface = "can0"\n\n[[can]]\ninterface = "can1"\n'
for line in a b; do
  iface=can0; [ "$line" = b ] && iface=can1
  for n in 0 1 2 3 4 5 6 7 8 9 10 11 12 13 14 15; do
    printf '\n[[pump]]\nname = "%s%02d"\nnode_id = %d\ninterface = "%s"\nmotor = "han2019-tmp"\nthermal_model = "tmp-generic"\nframe_sensor_lag_s = 30.0\n' \
      "$line" "$n" "$n" "$iface"
  done
done
