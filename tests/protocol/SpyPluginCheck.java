package pumptherm.spy;

import lcm.lcm.LCMDataInputStream;
import lcm.lcm.LCMDataOutputStream;
import lcm.spy.ChannelData;

/**
 * The pumptherm view without a display (java.awt.headless): statuses and reasons by name, codes
 * the types do not name as numbers, NaN as "-", a field the type lacks read as absent, the
 * pump's alarm state in its temperatures view (from the ALARM channel of the same pump only), and
 * which fingerprints the plugin takes. Exit status 1 and a FAIL line per failed check.
 */
public final class SpyPluginCheck {
  private static int failures = 0;

  private static void expect(boolean ok, String what) {
    if (!ok) {
      System.err.println("FAIL: " + what);
      ++failures;
    }
  }

  /** Alarm messages the views read, filled by the checks instead of an LCM subscription. */
  private static final PumpthermSpyPlugin.AlarmFeed alarms = new PumpthermSpyPlugin.AlarmFeed();

  /** A temperatures_t field under its name of protocol version "pumptherm 1" (an old jar). */
  public static final class Version1Temperatures {
    public double resistance_winding_degC = 61.25;
  }

  private static PumpthermSpyPlugin.View view(String channel, Object message) {
    ChannelData cd = new ChannelData();
    cd.name = channel;
    cd.last = message;
    return new PumpthermSpyPlugin.View(cd, alarms);
  }

  public static void main(String[] args) throws java.io.IOException {
    pumptherm.temperatures_t t = new pumptherm.temperatures_t();
    t.pump = "p1";
    t.ident_status = pumptherm.temperatures_t.IDENT_CONVERGED;
    t.filter_status = 9;  // no FILTER_ constant has this value
    t.nis = Double.NaN;
    t.magnet_flux_degC = Double.NaN;
    t.num_nodes = 2;
    t.node_names = new String[] {"frame", "rotor"};
    t.node_degC = new double[] {41.24, Double.NaN};
    t.node_sd_K = new double[] {0.5, 1.25};
    PumpthermSpyPlugin.View tv = view("PUMPTHERM/p1/TEMPS", t);
    String h = tv.header.getText();
    expect(h.contains("identification: <b>converged</b>"), "ident status by name: " + h);
    expect(h.contains("filter: <b>code 9</b>"), "unknown filter status as its number: " + h);
    expect(h.contains("NIS -"), "NaN as '-': " + h);
    expect(tv.model.getRowCount() == 2, "two node rows: " + tv.model.getRowCount());
    expect("frame".equals(tv.model.getValueAt(0, 0)) && "41.2".equals(tv.model.getValueAt(0, 1))
               && "1.0".equals(tv.model.getValueAt(0, 2)),
           "row frame 41.2 and its +-2 sd 1.0: " + tv.model.getValueAt(0, 0) + " "
               + tv.model.getValueAt(0, 1) + " " + tv.model.getValueAt(0, 2));
    expect("-".equals(tv.model.getValueAt(1, 1)), "NaN node temperature as '-'");
    expect(h.contains("alarm: <b>no ALARM message yet</b>"), "no alarm_t yet: " + h);
    expect(h.contains("magnet from flux: not available"), "no magnet from flux: " + h);

    pumptherm.alarm_t a = new pumptherm.alarm_t();
    a.pump = "p2";
    a.level = pumptherm.alarm_t.LEVEL_TRIP;
    a.time_to_trip_s = Double.POSITIVE_INFINITY;
    a.forecast_node = "rotor";
    a.num_conditions = 2;
    a.conditions = new pumptherm.alarm_condition_t[] {new pumptherm.alarm_condition_t(),
                                                      new pumptherm.alarm_condition_t()};
    a.conditions[0].level = pumptherm.alarm_t.LEVEL_TRIP;
    a.conditions[0].reason = pumptherm.alarm_condition_t.REASON_MEASURED_OVER_TEMPERATURE;
    a.conditions[0].node = "frame";
    a.conditions[1].level = pumptherm.alarm_t.LEVEL_WARNING;
    a.conditions[1].reason = 42;  // no REASON_ constant has this value
    a.conditions[1].node = "rotor";
    PumpthermSpyPlugin.View av = view("PUMPTHERM/p2/ALARM", a);
    expect(av.header.getText().contains("alarm: <b>trip</b>"), "alarm level by name: " + av.header.getText());
    expect(!av.header.getText().contains("time to trip"), "no time to trip when there is none: " + av.header.getText());
    expect(av.model.getRowCount() == 2, "two condition rows");
    expect("measured over temperature".equals(av.model.getValueAt(0, 1)), "reason by name: " + av.model.getValueAt(0, 1));
    expect("code 42".equals(av.model.getValueAt(1, 1)), "unknown reason as its number: " + av.model.getValueAt(1, 1));

    // The pump's alarm state in its temperatures view: the level and every reason by name in the
    // header, each node's conditions in its row; an alarm of another pump changes nothing.
    alarms.put("PUMPTHERM/p2/ALARM", a);
    tv.refresh();
    expect(tv.header.getText().contains("alarm: <b>no ALARM message yet</b>"),
           "another pump's alarm shown: " + tv.header.getText());
    a.pump = "p1";
    // Through the subscriber's decoding, as an LCM message of PUMPTHERM/p1/ALARM arrives.
    LCMDataOutputStream out = new LCMDataOutputStream();
    a.encode(out);
    alarms.messageReceived(null, "PUMPTHERM/p1/ALARM", new LCMDataInputStream(out.toByteArray()));
    tv.refresh();
    h = tv.header.getText();
    expect(h.contains("alarm: <b>trip (measured over temperature, code 42)</b>"), "alarm level and reasons: " + h);
    expect("trip: measured over temperature".equals(tv.model.getValueAt(0, 3)),
           "frame's condition in its row: " + tv.model.getValueAt(0, 3));
    expect("warning: code 42".equals(tv.model.getValueAt(1, 3)), "rotor's condition in its row: " + tv.model.getValueAt(1, 3));
    pumptherm.alarm_t normal = new pumptherm.alarm_t();
    normal.pump = "p1";
    normal.level = pumptherm.alarm_t.LEVEL_NORMAL;
    normal.conditions = new pumptherm.alarm_condition_t[0];
    normal.forecast_node = "";
    alarms.put("PUMPTHERM/p1/ALARM", normal);
    tv.refresh();
    expect(tv.header.getText().contains("alarm: <b>normal</b>"), "normal: " + tv.header.getText());
    expect("-".equals(tv.model.getValueAt(0, 3)), "no condition on frame: " + tv.model.getValueAt(0, 3));
    expect(PumpthermSpyPlugin.alarmChannelOf("PUMPTHERM/GATEWAY/HEALTH") == null, "ALARM channel of a non-TEMPS channel");

    // A forecast with a time to trip, and the diagnosis in the journal's words.
    pumptherm.alarm_t w = new pumptherm.alarm_t();
    w.pump = "p3";
    w.level = pumptherm.alarm_t.LEVEL_WARNING;
    w.time_to_trip_s = 276.2;
    w.forecast_node = "winding";
    w.conditions = new pumptherm.alarm_condition_t[0];
    w.mismatch_state = pumptherm.alarm_t.MISMATCH_PLANT_CHANGE;
    w.mismatch_effect = pumptherm.alarm_t.EFFECT_FRAME_AMBIENT_RESISTANCE;
    w.mismatch_value = 20.0;
    w.mismatch_since_utime = 1767225841000000L;  // 2026-01-01 00:04:01 UTC
    java.util.TimeZone.setDefault(java.util.TimeZone.getTimeZone("UTC"));
    h = view("PUMPTHERM/p3/ALARM", w).header.getText();
    expect(h.contains("time to trip 4 min 36 s (winding)"), "time to trip in minutes: " + h);
    expect(h.contains("diagnosis: cooling lost (frame-to-ambient resistance x20 or more) since 2026-01-01 00:04:01 UTC"),
           "diagnosis in words with its date: " + h);

    // Telemetry with the digits a reader needs (lcm-spy's structure view prints 100.70000000000002).
    pumptherm.telemetry_t m = new pumptherm.telemetry_t();
    m.pump = "p1";
    m.frame_sensor_degC = 100.70000000000002;
    m.ambient_degC = 22.2;
    m.coolant_degC = Double.NaN;
    m.drive_state = pumptherm.telemetry_t.DRIVE_STATE_STEADY;
    PumpthermSpyPlugin.View mv = view("PUMPTHERM/p1/TELEMETRY", m);
    expect("100.7".equals(mv.model.getValueAt(0, 1)), "frame sensor to 0.1 K: " + mv.model.getValueAt(0, 1));
    expect(mv.header.getText().contains("drive: <b>steady</b>"), "drive state by name: " + mv.header.getText());

    // Health: frame rates from the counts of two messages when the message carries none.
    pumptherm.gateway_health_t g = new pumptherm.gateway_health_t();
    g.utime = 1000000L;
    g.num_interfaces = 1;
    g.interfaces = new pumptherm.interface_health_t[] {new pumptherm.interface_health_t()};
    g.interfaces[0].name = "can0";
    g.interfaces[0].rx_frames_per_s = Double.NaN;
    g.interfaces[0].tx_frames_per_s = Double.NaN;
    g.interfaces[0].rx_frames = 1000;
    ChannelData hd = new ChannelData();
    hd.name = "PUMPTHERM/GATEWAY/HEALTH";
    hd.last = g;
    PumpthermSpyPlugin.View hv = new PumpthermSpyPlugin.View(hd, alarms);
    expect("-".equals(hv.model.getValueAt(0, 2)), "no rate from one message: " + hv.model.getValueAt(0, 2));
    pumptherm.gateway_health_t g2 = g.copy();
    g2.utime = 6000000L;
    g2.interfaces[0].rx_frames = 6000;
    hd.last = g2;
    hv.refresh();
    expect("1000".equals(hv.model.getValueAt(0, 2)), "rx frames/s from the counts: " + hv.model.getValueAt(0, 2));
    expect(!hv.header.getText().contains("MQTT"), "no MQTT without the sink: " + hv.header.getText());
    pumptherm.gateway_health_t g3 = g2.copy();
    g3.mqtt_enabled = true;
    g3.mqtt_dropped = 441;
    g3.mqtt_alarms_dropped = 0;
    hd.last = g3;
    hv.refresh();
    expect(hv.header.getText().contains("MQTT not connected, dropped: 441 steps, 0 alarms"),
           "the MQTT sink's drops: " + hv.header.getText());

    expect(PumpthermSpyPlugin.get(t, "no_such_field_degC") == null, "a field the type lacks reads as absent");
    PumpthermSpyPlugin plugin = new PumpthermSpyPlugin();
    expect(plugin.canHandle(pumptherm.temperatures_t.LCM_FINGERPRINT), "takes temperatures_t");
    expect(plugin.canHandle(pumptherm.alarm_t.LCM_FINGERPRINT), "takes alarm_t");
    expect(plugin.canHandle(pumptherm.telemetry_t.LCM_FINGERPRINT), "takes telemetry_t");
    expect(plugin.canHandle(pumptherm.gateway_health_t.LCM_FINGERPRINT), "takes gateway_health_t");
    expect(!plugin.canHandle(pumptherm.alarm_clear_t.LCM_FINGERPRINT), "leaves alarm_clear_t to lcm-spy");
    // A message of the types before "pumptherm 2" (an old log under the old jar) reads the same.
    Object v1 = PumpthermSpyPlugin.get(
        new Version1Temperatures(), "winding_resistance_degC", "resistance_winding_degC");
    expect(Double.valueOf(61.25).equals(v1), "the field under its pumptherm 1 name: " + v1);
    t.winding_resistance_degC = 84.25;
    t.resistance_ohm = 0.3;
    Object v2 = PumpthermSpyPlugin.get(t, "winding_resistance_degC", "resistance_winding_degC");
    expect(Double.valueOf(84.25).equals(v2), "the field under its current name: " + v2);
    System.out.println(failures == 0 ? "pumptherm view: all checks passed" : failures + " checks failed");
    System.exit(failures == 0 ? 0 : 1);  // also stops the views' timers
  }
}
