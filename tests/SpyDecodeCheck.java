// Decodes every event of an LCM log the way lcm-spy does: the message types are found on the
// classpath by lcm.util.ClassDiscoverer (as lcm.spy.Spy finds them) and matched by
// fingerprint. Prints "CHANNEL type" per channel; exits 1 if any event has no type or fails
// to decode.
import java.io.ByteArrayInputStream;
import java.io.DataInputStream;
import java.io.EOFException;
import java.util.HashMap;
import java.util.Map;
import java.util.TreeMap;
import lcm.logging.Log;
import lcm.util.ClassDiscoverer;

public class SpyDecodeCheck {
  public static void main(String[] args) throws Exception {
    final Map<Long, Class<?>> types = new HashMap<>();
    ClassDiscoverer.findClasses(new ClassDiscoverer.ClassVisitor() {
      public void classFound(String jar, Class cls) {
        try {
          types.put(cls.getField("LCM_FINGERPRINT").getLong(null), cls);
        } catch (Exception e) {
          // Not an LCM type.
        }
      }
    });
    Log log = new Log(args[0], "r");
    Map<String, String> decoded = new TreeMap<>();
    int failures = 0;
    while (true) {
      Log.Event e;
      try {
        e = log.readNext();
      } catch (EOFException end) {
        break;
      }
      if (e.channel.equals("LCM_SELF_TEST")) continue;
      long fingerprint = new DataInputStream(new ByteArrayInputStream(e.data)).readLong();
      Class<?> cls = types.get(fingerprint);
      if (cls == null) {
        System.out.println("NO TYPE for " + e.channel);
        failures++;
        continue;
      }
      try {
        cls.getConstructor(byte[].class).newInstance((Object) e.data);
        decoded.put(e.channel, cls.getName());
      } catch (Exception x) {
        System.out.println("DECODE FAILED " + e.channel + ": " + x.getCause());
        failures++;
      }
    }
    for (Map.Entry<String, String> kv : decoded.entrySet()) {
      System.out.println(kv.getKey() + " " + kv.getValue());
    }
    System.exit(failures == 0 ? 0 : 1);
  }
}
