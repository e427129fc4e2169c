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
 * lcm-spy plugin: a pump's temperatures_t as a table (node, degC, sd) with the status bytes by
 * name and the pump's alarm state (level, reasons by name, per node in the table), and an alarm_t
 * as its level and one row per condition with the reason by name.
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
    return fp != 0 && (fp == fingerprint(TEMPERATURES) || fp == fingerprint(ALARM));
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

  /** The internal frame: a header line and a table, refreshed from ChannelData.last. */
  static final class View extends JInternalFrame {
    private static final long serialVersionUID = 1L;
    private final ChannelData cd;
    private final AlarmFeed alarms;
    final JLabel header = new JLabel(" ");  // package-private: read by tests/protocol/SpyPluginCheck
    final DefaultTableModel model = new DefaultTableModel();
    private Object shown;
    private Object shownAlarm;

    View(ChannelData cd, AlarmFeed alarms) {
      super(cd.name + " (pumptherm)", true, true, true, true);
      this.cd = cd;
      this.alarms = alarms;
      setLayout(new BorderLayout());
      add(header, BorderLayout.NORTH);
      JTable table = new JTable(model);
      table.setEnabled(false);
      add(new JScrollPane(table), BorderLayout.CENTER);
      setSize(480, 360);  // lcm-spy's plugin window is 500 x 400
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
      shown = m;
      shownAlarm = alarm;
      String cls = m.getClass().getName();
      if (cls.equals(TEMPERATURES)) showTemperatures(m, alarm);
      else if (cls.equals(ALARM)) showAlarm(m);
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

    private void showTemperatures(Object m, Object alarm) {
      Class<?> c = m.getClass();
      header.setText(String.format(
          "<html>pump <b>%s</b> &nbsp; alarm: <b>%s</b>"
              + "<br>identification: <b>%s</b> &nbsp; filter: <b>%s</b> &nbsp; NIS %s"
              + "<br>resistance %s ohm (sd %s) &nbsp; winding from resistance %s degC (sd %s K)</html>",
          get(m, "pump"), alarmText(alarm), codeName(c, "IDENT_", get(m, "ident_status")),
          codeName(c, "FILTER_", get(m, "filter_status")), num(get(m, "nis"), "%.2f"),
          num(get(m, "resistance_ohm"), "%.4f"), num(get(m, "resistance_sd_ohm"), "%.4f"),
          num(get(m, "resistance_winding_degC"), "%.1f"), num(get(m, "resistance_winding_sd_K"), "%.1f")));
      Object names = get(m, "node_names");
      Object deg = get(m, "node_degC");
      Object sd = get(m, "node_sd_K");
      int n = names != null && names.getClass().isArray() ? Array.getLength(names) : 0;
      summarise(String.format("pump %s, %d nodes, filter %s, alarm %s", get(m, "pump"), n,
                              codeName(c, "FILTER_", get(m, "filter_status")), alarmText(alarm)));
      Object[][] rows = new Object[n][];
      for (int i = 0; i < n; ++i) {
        Object node = element(names, i);
        rows[i] = new Object[] {node, num(element(deg, i), "%.1f"), num(element(sd, i), "%.2f"),
                                nodeAlarm(alarm, node)};
      }
      model.setDataVector(rows, new Object[] {"node", "degC", "sd, K", "alarm"});
    }

    private void showAlarm(Object m) {
      header.setText(String.format(
          "<html>pump <b>%s</b> &nbsp; alarm: <b>%s</b> &nbsp; time to trip %s s (forecast node %s)</html>",
          get(m, "pump"), codeName(m.getClass(), "LEVEL_", get(m, "level")),
          num(get(m, "time_to_trip_s"), "%.0f"), get(m, "forecast_node")));
      Object conditions = get(m, "conditions");
      List<Object[]> rows = new ArrayList<>();
      int n = conditions != null && conditions.getClass().isArray() ? Array.getLength(conditions) : 0;
      for (int i = 0; i < n; ++i) {
        Object k = Array.get(conditions, i);
        rows.add(new Object[] {codeName(m.getClass(), "LEVEL_", get(k, "level")),
                               reasonName(get(k, "reason")), get(k, "node"),
                               num(get(k, "value_degC"), "%.1f"), num(get(k, "threshold_degC"), "%.1f"),
                               num(get(k, "rate_K_per_s"), "%.4f"), get(k, "latched")});
      }
      StringBuilder reasons = new StringBuilder();
      for (Object[] row : rows) reasons.append(reasons.length() == 0 ? "" : ", ").append(row[1]);
      summarise(String.format("pump %s, alarm %s, conditions: %s", get(m, "pump"),
                              codeName(m.getClass(), "LEVEL_", get(m, "level")),
                              rows.isEmpty() ? "none" : reasons));
      model.setDataVector(rows.toArray(new Object[0][]),
                          new Object[] {"level", "reason", "node", "degC", "threshold degC", "K/s", "latched"});
    }
  }
}
