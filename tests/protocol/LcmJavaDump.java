// Helper of lcm_java_test.cpp: decodes LCM-encoded files with the Java classes of
// pumptherm_lcm_types.jar (the ones lcm-spy uses), prints every field, and re-encodes them.
//
//   java -cp lcm.jar:pumptherm_lcm_types.jar:lcm_java_dump.jar LcmJavaDump DUMP TYPE IN OUT [TYPE IN OUT]...
//
// For each triple: decodes IN as pumptherm.TYPE, writes the Java encoding of the decoded object
// to OUT, and writes a line "#TYPE" then "TYPE.path=value" per non-static field to DUMP in
// UTF-8 (arrays as
// path[i], nested types as path.field; doubles with Double.toString, which round-trips
// exactly; strings as they are).
// Exit code 1 and a message on stderr when a file does not decode.

import java.io.ByteArrayOutputStream;
import java.io.DataOutputStream;
import java.lang.reflect.Array;
import java.lang.reflect.Field;
import java.lang.reflect.Modifier;
import java.nio.charset.StandardCharsets;
import java.nio.file.Files;
import java.nio.file.Paths;

public final class LcmJavaDump {
  private LcmJavaDump() {}

  public static void main(String[] args) throws Exception {
    if (args.length < 4 || args.length % 3 != 1) {
      System.err.println("usage: LcmJavaDump DUMP TYPE IN OUT [TYPE IN OUT]...");
      System.exit(2);
    }
    StringBuilder out = new StringBuilder();
    for (int i = 1; i < args.length; i += 3) {
      String type = args[i];
      byte[] in = Files.readAllBytes(Paths.get(args[i + 1]));
      Object message;
      try {
        message = Class.forName("pumptherm." + type).getConstructor(byte[].class).newInstance((Object) in);
      } catch (java.lang.reflect.InvocationTargetException e) {
        System.err.println(args[i + 1] + ": does not decode as " + type + ": " + e.getCause());
        System.exit(1);
        return;
      }
      ByteArrayOutputStream bytes = new ByteArrayOutputStream();
      ((lcm.lcm.LCMEncodable) message).encode(new DataOutputStream(bytes));
      Files.write(Paths.get(args[i + 2]), bytes.toByteArray());
      out.append('#').append(type).append('\n');
      Dump(type, message, out);
    }
    Files.write(Paths.get(args[0]), out.toString().getBytes(StandardCharsets.UTF_8));
  }

  private static void Dump(String path, Object value, StringBuilder out) throws IllegalAccessException {
    if (value == null) {
      out.append(path).append("=null\n");
    } else if (value.getClass().isArray()) {
      for (int i = 0; i < Array.getLength(value); ++i) {
        Dump(path + "[" + i + "]", Array.get(value, i), out);
      }
    } else if (value instanceof lcm.lcm.LCMEncodable) {
      for (Field field : value.getClass().getFields()) {
        if (!Modifier.isStatic(field.getModifiers())) {
          Dump(path + "." + field.getName(), field.get(value), out);
        }
      }
    } else {
      out.append(path).append('=').append(value).append('\n');
    }
  }
}
