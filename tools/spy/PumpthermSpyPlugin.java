package pumptherm.spy;

import java.awt.BorderLayout;
import java.awt.event.ActionEvent;
import java.io.DataInput;
import java.lang.reflect.Array;
import java.lang.reflect.Constructor;
import java.lang.reflect.Field;
import java.lang.reflect.Modifier;
import java.util.ArrayList;
import java.util.LinkedHashSet;
import java.util.List;
import java.util.Map;
import java.util.Set;
import java.util.concurrent.ConcurrentHashMap;
import javax.swing.AbstractAction;
import javax.swing.Action;
import javax.swing.JDesktopPane;
import javax.swing.JInternalFrame;
import javax.swing.JLabel;
import javax.swing.JScrollPane;
import javax.swing.JTable;
import javax.swing.Timer;
import javax.swing.table.DefaultTableModel;
import lcm.lcm.LCM;
import lcm.lcm.LCMDataInputStream;
import lcm.lcm.LCMSubscriber;
import lcm.spy.ChannelData;
import lcm.spy.SpyPlugin;

/**
 * lcm-spy plugin: pumptherm's messages in words and with the digits a reader needs (lcm-spy's
 * own structure view prints every double with all its digits and draws a constant's name over
 * its value). A pump's temperatures_t as a table (node, degC, +-2 sd) with the statuses by name,
 * the winding from resistance and the magnet from flux, and the pump's alarm state and diagnosis;
 * an alarm_t as its level, diagnosis and one row per condition; a telemetry_t as its readings
 * with units; a gateway_health_t as one row per interface, frame rates from the counts when the
 * message carries none. lcm-spy opens this view on a double click (it takes the first plugin
 * that handles a type); its structure view stays in the right-click menu.
 *
 * <p>lcm-spy hands a plugin one channel, so the temperatures view takes the alarm state of the
 * same pump (channel PREFIX/PUMP/ALARM beside PREFIX/PUMP/TEMPS) from a subscription of the
 * plugin's own, on the LCM URL that pumptherm-spy passes as the system property
 * pumptherm.spy.lcm_url (LCM's default URL without it, as lcm-spy's own).
 *
 * <p>Fields are read by name through reflection, so a message type that gains fields still shows
 * (missing ones print as "-"), and a status or reason code without a constant of that name in
 * the type prints as its number. The view polls the channel's last decoded message four times a
 * second (lcm-spy keeps it in ChannelData.last).
 */
public class PumpthermSpyPlugin implements SpyPlugin {
  static final String TEMPERATURES = "pumptherm.temperatures_t";
  static final String ALARM = "pumptherm.alarm_t";
  static final String CONDITION = "pumptherm.alarm_condition_t";
  static final String TELEMETRY = "pumptherm.telemetry_t";
  static final String HEALTH = "pumptherm.gateway_health_t";
  static final String INTERFACE = "pumptherm.interface_health_t";
  static final String URL_PROPERTY = "pumptherm.spy.lcm_url";

  /** The ALARM channel of the pump whose TEMPS channel is `channel`, or null for another name. */
  static String alarmChannelOf(String channel) {
    return channel != null && channel.endsWith("/TEMPS")
        ? channel.substring(0, channel.length() - "TEMPS".length()) + "ALARM"
        : null;
  }

  /** The last alarm_t of each ALARM channel, decoded from the plugin's own subscription. */
  static final class AlarmFeed implements LCMSubscriber {
    private final Map<String, Object> last = new ConcurrentHashMap<>();
    private volatile String problem;  // why no alarm can arrive, or null

    /** The last alarm_t on `channel`, or null when none arrived. */
    Object last(String channel) {
      return channel == null ? null : last.get(channel);
    }

    /** Records `alarm` as the last message of `channel` (what the subscription does). */
    void put(String channel, Object alarm) {
      last.put(channel, alarm);
    }

    /** Why no alarm_t can arrive (no LCM, no alarm_t type), or null when they can. */
    String problem() {
      return problem;
    }

    void setProblem(String why) {
      problem = why;
    }

    @Override
    public void messageReceived(LCM lcm, String channel, LCMDataInputStream ins) {
      try {
        Constructor<?> decode = Class.forName(ALARM).getConstructor(DataInput.class);
        put(channel, decode.newInstance(ins));
      } catch (ReflectiveOperationException | LinkageError e) {
        // not an alarm_t (another type on a channel named .../ALARM): not this pump's state
      }
    }
  }

  private static AlarmFeed feed;

  /** The feed every temperatures view reads, subscribed on first use. */
  static synchronized AlarmFeed sharedFeed() {
    if (feed != null) return feed;
    feed = new AlarmFeed();
    String url = System.getProperty(URL_PROPERTY);
    try {
      LCM lcm = url == null || url.isEmpty() ? new LCM() : new LCM(url);
      lcm.subscribe(".*/ALARM", feed);
    } catch (java.io.IOException | RuntimeException e) {
      feed.setProblem("no LCM subscription (" + e.getMessage() + ")");
    }
    return feed;
  }

  /** The fingerprint of a generated type, or 0 when the type is not on the class path. */
  static long fingerprint(String cls) {
    try {
      return Class.forName(cls).getField("LCM_FINGERPRINT").getLong(null);
    } catch (ReflectiveOperationException | LinkageError e) {
      return 0;
    }
  }

  @Override
  public boolean canHandle(long fp) {
    if (fp == 0) return false;
    for (String cls : new String[] {TEMPERATURES, ALARM, TELEMETRY, HEALTH})
      if (fp == fingerprint(cls)) return true;
    return false;
  }

  @Override
  public Action getAction(JDesktopPane desktop, ChannelData cd) {
    return new AbstractAction("pumptherm view") {
      @Override
      public void actionPerformed(ActionEvent e) {
        View view = new View(cd, sharedFeed());
        desktop.add(view);
        view.setVisible(true);
      }
    };
  }

  /** The field `name` of `o`, or null when `o` is null or has no such public field. */
  static Object get(Object o, String name) {
    if (o == null) return null;
    try {
      return o.getClass().getField(name).get(o);
    } catch (ReflectiveOperationException e) {
      return null;
    }
  }

  /**
   * Field `name` of `o`, or else its name of protocol version "pumptherm 1" (`before`): a log
   * recorded before the rename is decoded only by the types jar of that version (the
   * fingerprint changed), and this view shows it the same (docs/lcm.md, "Protocol versions").
   */
  static Object get(Object o, String name, String before) {
    Object v = get(o, name);
    return v != null ? v : get(o, before);
  }

  /** The static constant of `cls` whose name starts with `prefix` and equals `code`. */
  static String codeName(Class<?> cls, String prefix, Object code) {
    if (code == null) return "-";
    if (cls != null) {
      for (Field f : cls.getFields()) {
        if (!Modifier.isStatic(f.getModifiers()) || !f.getName().startsWith(prefix)) continue;
        try {
          if (String.valueOf(f.get(null)).equals(String.valueOf(code)))
            return f.getName().substring(prefix.length()).toLowerCase().replace('_', ' ');
        } catch (IllegalAccessException e) {
          // not readable: try the next constant
        }
      }
    }
    return "code " + code;
  }

  /** A number with the digits a temperature display needs; NaN prints as "-". */
  static String num(Object v, String fmt) {
    if (!(v instanceof Number)) return v == null ? "-" : String.valueOf(v);
    double d = ((Number) v).doubleValue();
    return Double.isFinite(d) ? String.format(fmt, d) : "-";
  }

  /** A duration for people, as the journal writes it: "45 s", "4 min 36 s", "5 min", "2 h 05 min". */
  static String duration(Object v) {
    if (!(v instanceof Number) || !Double.isFinite(((Number) v).doubleValue())) return "never";
    long s = Math.round(Math.max(0.0, ((Number) v).doubleValue()));
    if (s < 60) return s + " s";
    if (s < 3600) return s % 60 == 0 ? (s / 60) + " min" : String.format("%d min %02d s", s / 60, s % 60);
    return (s % 3600) / 60 == 0 ? (s / 3600) + " h" : String.format("%d h %02d min", s / 3600, (s % 3600) / 60);
  }

  /** A utime (us since the Unix epoch) as local time, "2026-01-01 00:04:01 UTC"; "-" for 0. */
  static String localTime(Object utime) {
    if (!(utime instanceof Number) || ((Number) utime).longValue() <= 0) return "-";
    java.time.ZonedDateTime t = java.time.Instant.ofEpochMilli(((Number) utime).longValue() / 1000)
        .atZone(java.time.ZoneId.systemDefault());
    return t.format(java.time.format.DateTimeFormatter.ofPattern("yyyy-MM-dd HH:mm:ss z"));
  }

  /** A condition's reason by the name of its REASON_ constant in alarm_condition_t. */
  static String reasonName(Object code) {
    Class<?> condition = null;
    try {
      condition = Class.forName(CONDITION);
    } catch (ClassNotFoundException | LinkageError e) {
      // reasons print as numbers
    }
    return codeName(condition, "REASON_", code);
  }

  static Object element(Object array, int i) {
    return array != null && array.getClass().isArray() && i < Array.getLength(array) ? Array.get(array, i) : null;
  }

  static double number(Object v) {
    return v instanceof Number ? ((Number) v).doubleValue() : Double.NaN;
  }

  /** `v` to three significant figures without trailing zeros, as C's %.3g: "20", "1.81". */
  static String threeFigures(double v) {
    if (!Double.isFinite(v)) return "-";
    return new java.math.BigDecimal(String.format(java.util.Locale.ROOT, "%.3g", v))
        .stripTrailingZeros().toPlainString();
  }

  /**
   * The model diagnosis of an alarm_t in the journal's words, "cooling lost (frame-to-ambient
   * resistance x20 or more) since 2026-01-01 00:04:01 UTC", or "model consistent"; "" when the
   * message has no mismatch fields.
   */
  static String diagnosis(Object alarm) {
    if (alarm == null || get(alarm, "mismatch_state") == null) return "";
    String state = codeName(alarm.getClass(), "MISMATCH_", get(alarm, "mismatch_state"));
    if (!state.equals("plant change") && !state.equals("sensor fault suspected")
        && !state.equals("unexplained")) {
      return "model " + state;
    }
    String effect = codeName(alarm.getClass(), "EFFECT_", get(alarm, "mismatch_effect"));
    double v = number(get(alarm, "mismatch_value"));
    String cause;
    switch (effect) {
      case "frame ambient resistance":
        cause = String.format("%s (frame-to-ambient resistance x%s%s)",
                              v >= 2 ? "cooling lost" : v > 1 ? "cooling reduced" : "cooling better than modelled",
                              threeFigures(v), v >= 20 ? " or more" : "");
        break;
      case "rotor loss":
        cause = String.format("heat inside the rotor (%+.0f W: bearing, gas friction)", v);
        break;
      case "loss scale":
        cause = String.format("%s heat than modelled (losses x%.2f)", v >= 1 ? "more" : "less", v);
        break;
      case "unmeasured ambient":
        cause = String.format("surroundings %s than the ambient sensor reads (%+.1f K)",
                              v >= 0 ? "warmer" : "cooler", v);
        break;
      case "sensor offset":
        cause = String.format("sensor reads %+.1f K off (the sensor, not the plant)", v);
        break;
      case "sensor stuck":
        cause = String.format("sensor stuck at %.1f degC (the sensor, not the plant)", v);
        break;
      default:
        cause = "the model no longer explains the sensor (cause not named yet)";
    }
    String since = localTime(get(alarm, "mismatch_since_utime"));
    return since.equals("-") ? cause : cause + " since " + since;
  }

  /** Every column as wide as its widest cell or header, so that no text is cut. */
  static int fitColumns(JTable table) {
    int total = 0;
    for (int c = 0; c < table.getColumnCount(); ++c) {
      javax.swing.table.TableColumn col = table.getColumnModel().getColumn(c);
      java.awt.Component h = table.getTableHeader().getDefaultRenderer()
          .getTableCellRendererComponent(table, col.getHeaderValue(), false, false, -1, c);
      int w = h.getPreferredSize().width;
      for (int r = 0; r < table.getRowCount(); ++r) {
        java.awt.Component cell = table.prepareRenderer(table.getCellRenderer(r, c), r, c);
        w = Math.max(w, cell.getPreferredSize().width);
      }
      col.setPreferredWidth(w + 12);
      total += w + 12;
    }
    return total;
  }

  /** The internal frame: a header line and a table, refreshed from ChannelData.last. */
  static final class View extends JInternalFrame {
    private static final long serialVersionUID = 1L;
    private final ChannelData cd;
    private final AlarmFeed alarms;
    final JLabel header = new JLabel(" ");  // package-private: read by tests/protocol/SpyPluginCheck
    final DefaultTableModel model = new DefaultTableModel();
    final JTable table = new JTable(model);
    private Object shown;
    private Object shownAlarm;

    View(ChannelData cd, AlarmFeed alarms) {
      super(cd.name + " (pumptherm)", true, true, true, true);
      this.cd = cd;
      this.alarms = alarms;
      setLayout(new BorderLayout());
      add(header, BorderLayout.NORTH);
      table.setEnabled(false);
      table.setAutoResizeMode(JTable.AUTO_RESIZE_OFF);
      add(new JScrollPane(table), BorderLayout.CENTER);
      setSize(560, 360);
      Timer timer = new Timer(250, e -> refresh());
      timer.start();
      addInternalFrameListener(new javax.swing.event.InternalFrameAdapter() {
        @Override
        public void internalFrameClosed(javax.swing.event.InternalFrameEvent e) {
          timer.stop();
        }
      });
      refresh();
    }

    /** Redraws when the channel's message, or (temperatures) the pump's alarm_t, changed. */
    void refresh() {
      Object m = cd.last;
      Object alarm = alarms.last(alarmChannelOf(cd.name));
      if (m == null || (m == shown && alarm == shownAlarm)) return;
      Object before = shown;
      shown = m;
      shownAlarm = alarm;
      String cls = m.getClass().getName();
      if (cls.equals(TEMPERATURES)) showTemperatures(m, alarm);
      else if (cls.equals(ALARM)) showAlarm(m);
      else if (cls.equals(TELEMETRY)) showTelemetry(m);
      else if (cls.equals(HEALTH)) showHealth(m, before);
      int width = fitColumns(table);
      if (getWidth() < width + 24) setSize(width + 24, getHeight());
    }

    /** The summary in the enclosing window's title, "CHANNEL: summary" (what a test can read). */
    private void summarise(String text) {
      java.awt.Window w = javax.swing.SwingUtilities.getWindowAncestor(this);
      if (w instanceof java.awt.Frame) ((java.awt.Frame) w).setTitle(cd.name + ": " + text);
    }

    /** The alarm state in words: "trip (measured over temperature, rate of rise)". */
    private String alarmText(Object alarm) {
      if (alarm == null) {
        String why = alarms.problem();
        return why == null ? "no ALARM message yet" : "not known: " + why;
      }
      Set<String> reasons = new LinkedHashSet<>();
      Object conditions = get(alarm, "conditions");
      int n = conditions != null && conditions.getClass().isArray() ? Array.getLength(conditions) : 0;
      for (int i = 0; i < n; ++i) reasons.add(reasonName(get(Array.get(conditions, i), "reason")));
      String level = codeName(alarm.getClass(), "LEVEL_", get(alarm, "level"));
      return reasons.isEmpty() ? level : level + " (" + String.join(", ", reasons) + ")";
    }

    /** The conditions of `alarm` on `node`: "warning: rate of rise", "-" when none. */
    private static String nodeAlarm(Object alarm, Object node) {
      Object conditions = get(alarm, "conditions");
      int n = conditions != null && conditions.getClass().isArray() ? Array.getLength(conditions) : 0;
      List<String> parts = new ArrayList<>();
      for (int i = 0; i < n; ++i) {
        Object k = Array.get(conditions, i);
        if (node == null || !node.equals(get(k, "node"))) continue;
        parts.add(codeName(alarm.getClass(), "LEVEL_", get(k, "level")) + ": " + reasonName(get(k, "reason")));
      }
      return parts.isEmpty() ? (alarm == null ? "" : "-") : String.join(", ", parts);
    }

    /** "63.0 +-3.1 degC", or "not available" for no value. */
    private static String degC(String value) {
      return value.equals("-") ? "not available" : value + " degC";
    }

    /** "63.0 +-3.1": an estimate and its +-2 sd band, to 0.1 K. */
    private static String band(Object x, Object sd) {
      String v = num(x, "%.1f");
      double s = number(sd);
      return v.equals("-") || !Double.isFinite(s) ? v : v + " \u00b1" + String.format("%.1f", 2 * s);
    }

    private void showTemperatures(Object m, Object alarm) {
      Class<?> c = m.getClass();
      String diagnosis = diagnosis(alarm);
      header.setText(String.format(
          "<html>pump <b>%s</b> &nbsp; alarm: <b>%s</b>%s"
              + "<br>identification: <b>%s</b> &nbsp; filter: <b>%s</b> &nbsp; NIS %s"
              + "<br>winding from resistance: %s &nbsp; magnet from flux: %s"
              + " &nbsp; resistance %s ohm</html>",
          get(m, "pump"), alarmText(alarm), diagnosis.isEmpty() ? "" : "<br>diagnosis: " + diagnosis,
          codeName(c, "IDENT_", get(m, "ident_status")), codeName(c, "FILTER_", get(m, "filter_status")),
          num(get(m, "nis"), "%.2f"),
          degC(band(get(m, "winding_resistance_degC", "resistance_winding_degC"),
              get(m, "winding_resistance_sd_K", "resistance_winding_sd_K"))),
          degC(band(get(m, "magnet_flux_degC"), get(m, "magnet_flux_sd_K"))),
          num(get(m, "resistance_ohm"), "%.4f")));
      Object names = get(m, "node_names");
      Object deg = get(m, "node_degC");
      Object sd = get(m, "node_sd_K");
      int n = names != null && names.getClass().isArray() ? Array.getLength(names) : 0;
      summarise(String.format("pump %s, %d nodes, filter %s, alarm %s", get(m, "pump"), n,
                              codeName(c, "FILTER_", get(m, "filter_status")), alarmText(alarm)));
      Object[][] rows = new Object[n][];
      for (int i = 0; i < n; ++i) {
        Object node = element(names, i);
        double s = number(element(sd, i));
        rows[i] = new Object[] {node, num(element(deg, i), "%.1f"),
                                Double.isFinite(s) ? String.format("%.1f", 2 * s) : "-",
                                nodeAlarm(alarm, node)};
      }
      model.setDataVector(rows, new Object[] {"node", "estimate, degC", "\u00b12 sd, K", "alarm"});
    }

    private void showAlarm(Object m) {
      Class<?> c = m.getClass();
      double ttt = number(get(m, "time_to_trip_s"));
      String level = codeName(c, "LEVEL_", get(m, "level"));
      // A time to trip only when there is one (finite) and the pump has not tripped already.
      String forecast = Double.isFinite(ttt) && !level.equals("trip")
          ? String.format(" &nbsp; time to trip %s (%s)", duration(ttt), get(m, "forecast_node"))
          : "";
      String diagnosis = diagnosis(m);
      header.setText(String.format("<html>pump <b>%s</b> &nbsp; alarm: <b>%s</b>%s%s</html>",
                                   get(m, "pump"), level, forecast,
                                   diagnosis.isEmpty() ? "" : "<br>diagnosis: " + diagnosis));
      Object conditions = get(m, "conditions");
      List<Object[]> rows = new ArrayList<>();
      int n = conditions != null && conditions.getClass().isArray() ? Array.getLength(conditions) : 0;
      for (int i = 0; i < n; ++i) {
        Object k = Array.get(conditions, i);
        double rate = number(get(k, "rate_K_per_s"));
        rows.add(new Object[] {codeName(c, "LEVEL_", get(k, "level")), reasonName(get(k, "reason")),
                               get(k, "node"), num(get(k, "value_degC"), "%.1f"),
                               num(get(k, "threshold_degC"), "%.1f"),
                               Double.isFinite(rate) ? String.format("%.1f", rate * 60) : "-",
                               localTime(get(k, "since_utime")),
                               Boolean.TRUE.equals(get(k, "latched")) ? "latched" : ""});
      }
      StringBuilder reasons = new StringBuilder();
      for (Object[] row : rows) reasons.append(reasons.length() == 0 ? "" : ", ").append(row[1]);
      summarise(String.format("pump %s, alarm %s, conditions: %s", get(m, "pump"), level,
                              rows.isEmpty() ? "none" : reasons));
      model.setDataVector(rows.toArray(new Object[0][]),
                          new Object[] {"level", "reason", "node", "degC", "level, degC", "K/min", "since", ""});
    }

    private void showTelemetry(Object m) {
      Class<?> c = m.getClass();
      header.setText(String.format("<html>pump <b>%s</b> (node ID %s) &nbsp; drive: <b>%s</b>"
                                       + " &nbsp; at %s</html>",
                                   get(m, "pump"), get(m, "node_id"),
                                   codeName(c, "DRIVE_STATE_", get(m, "drive_state")),
                                   localTime(get(m, "utime"))));
      Object[][] rows = {
          {"frame sensor", num(get(m, "frame_sensor_degC", "frame_degC"), "%.1f"), "degC"},
          {"ambient", num(get(m, "ambient_degC"), "%.1f"), "degC"},
          {"coolant", num(get(m, "coolant_degC"), "%.1f"), "degC"},
          {"speed", num(get(m, "speed_rpm"), "%.0f"), "r/min"},
          {"id", num(get(m, "id_A"), "%.2f"), "A"},
          {"iq", num(get(m, "iq_A"), "%.2f"), "A"},
          {"ud", num(get(m, "ud_V"), "%.2f"), "V"},
          {"uq", num(get(m, "uq_V"), "%.2f"), "V"},
          {"DC link", num(get(m, "dc_link_V"), "%.1f"), "V"},
          {"age of the status values", num(get(m, "status_age_s"), "%.1f"), "s"},
          {"rolling counter", String.valueOf(get(m, "rolling_counter")), ""},
      };
      summarise(String.format("pump %s, drive %s", get(m, "pump"),
                              codeName(c, "DRIVE_STATE_", get(m, "drive_state"))));
      model.setDataVector(rows, new Object[] {"reading", "value", "unit"});
    }

    /** `before`: the gateway_health_t shown before (frame rates from the counts), or null. */
    private void showHealth(Object m, Object before) {
      Object list = get(m, "interfaces");
      int n = list != null && list.getClass().isArray() ? Array.getLength(list) : 0;
      double dt = before == null ? Double.NaN
          : (number(get(m, "utime")) - number(get(before, "utime"))) * 1e-6;
      Object[][] rows = new Object[n][];
      Class<?> ifc = n > 0 ? Array.get(list, 0).getClass() : null;
      for (int i = 0; i < n; ++i) {
        Object k = Array.get(list, i);
        Object old = before == null ? null : element(get(before, "interfaces"), i);
        rows[i] = new Object[] {get(k, "name"), codeName(ifc, "BUS_STATE_", get(k, "bus_state")),
                                rate(k, old, "rx", dt), rate(k, old, "tx", dt), get(k, "rx_frames"),
                                get(k, "tx_frames"), get(k, "rx_dropped"), get(k, "tx_dropped"),
                                get(k, "rx_rejected"), get(k, "error_frames"), get(k, "reopens")};
      }
      header.setText(String.format(
          "<html>gateway up %s &nbsp; %s pumps &nbsp; LCM messages not sent: %s%s<br>at %s</html>",
          duration(get(m, "uptime_s")), get(m, "num_pumps"), get(m, "lcm_publish_failures"),
          mqtt(m), localTime(get(m, "utime"))));
      summarise(String.format("%d interfaces, up %s", n, duration(get(m, "uptime_s"))));
      model.setDataVector(rows, new Object[] {"interface", "bus", "rx frames/s", "tx frames/s", "rx frames",
                                              "tx frames", "rx dropped", "tx dropped", "rx rejected",
                                              "error frames", "reopens"});
    }

    /**
     * The MQTT sink's part of the header: "" without [mqtt] (or in a message of a type before
     * the sink's fields).
     */
    private static String mqtt(Object m) {
      if (!Boolean.TRUE.equals(get(m, "mqtt_enabled"))) return "";
      return String.format(" &nbsp; MQTT %s, dropped: %s steps, %s alarms",
                           Boolean.TRUE.equals(get(m, "mqtt_connected")) ? "connected" : "not connected",
                           get(m, "mqtt_dropped"), get(m, "mqtt_alarms_dropped"));
    }

    /**
     * The frame rate of `dir` ("rx", "tx"): the message's own, else from the counts of this and
     * the previous message over `dt` seconds ("-" until two have arrived).
     */
    private static String rate(Object now, Object before, String dir, double dt) {
      double r = number(get(now, dir + "_frames_per_s"));
      if (Double.isFinite(r)) return String.format("%.0f", r);
      if (before == null || !(dt > 0)) return "-";
      double d = number(get(now, dir + "_frames")) - number(get(before, dir + "_frames"));
      return Double.isFinite(d) ? String.format("%.0f", d / dt) : "-";
    }
  }
}
