// libFuzzer: bytes from the bus into the core. The first byte picks a message type; the rest
// is decoded as that type (LCM checks the fingerprint and lengths) and, when it decodes, goes
// through the station's readers exactly as a daemon would take it: image conversion, capture
// sets, chunk reassembly of correspondences, point clouds, flat meshes (and the sheet rebuilt
// from the nodes) and the scan contexts they carry, textures, calibration, stage reports, the
// camera's answers to the display-lag measurement.
// Nothing may crash, hang or read out of bounds.
#include <cstddef>
#include <cstdint>

#include "core/patterns/display_lag.h"
#include "core/sim/gantry.h"
#include "station/messages.h"
#include "station/node.h"
#include "station/scan_store.h"
#include "vellum/latency_seen_t.hpp"
#include "vellum/light_t.hpp"

namespace vellum::station {
namespace {

// As the daemons decode (Node::Subscribe): through SafeDecode.
template <class Msg>
bool Decode(const uint8_t* data, size_t size, Msg* msg) {
  return size < (64u << 20) && SafeDecode(data, static_cast<int64_t>(size), msg);
}

}  // namespace
}  // namespace vellum::station

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace vellum;
  using namespace vellum::station;
  if (size < 1) return 0;
  const uint8_t kind = data[0] % 10;
  ++data;
  --size;
  switch (kind) {
    case 0: {
      image_t m;
      cv::Mat image;
      if (Decode(data, size, &m)) (void)FromMessage(m, &image);
      break;
    }
    case 1: {
      capture_t m;
      if (!Decode(data, size, &m)) break;
      CaptureSet set;
      if (set.Add(m).ok() && set.Complete()) (void)set.ToScan();
      break;
    }
    case 2: {
      correspondence_t m;
      if (!Decode(data, size, &m)) break;
      DecodeResult decoded;
      cv::Size projector;
      ChunkSet chunks;
      if (chunks.Add(m.scan_id, m.chunk_index, m.chunk_count, Clock::time_point()).ok()) {
        (void)AddChunk(m, &decoded, &projector);
      }
      ScanContext context;
      (void)FromMessage(m.context, &context);
      break;
    }
    case 3: {
      point_cloud_t m;
      if (!Decode(data, size, &m)) break;
      cv::Mat points;
      (void)AddChunk(m, &points);
      ScanContext context;
      (void)FromMessage(m.context, &context);
      break;
    }
    case 4: {
      mesh_t m;
      if (!Decode(data, size, &m)) break;
      Mesh mesh;
      FlattenResult flat;
      SheetPage page;
      SheetRests rests;
      if (AddChunk(m, &mesh, &flat, &page, &rests).ok() && m.chunk_count == 1) {
        static const Calibration rig = DefaultRig();
        ConnectSheet(
            m.bend_springs, [](const cv::Vec3d& x) { return rig.camera.Project(x); }, &mesh);
        if (mesh.status.ok()) (void)SetRestLengths(rests, &mesh);
      }
      break;
    }
    case 5: {
      calibration_t m;
      Calibration c;
      if (Decode(data, size, &m)) (void)FromMessage(m, &c);
      break;
    }
    case 6: {
      texture_t m;
      cv::Mat texture;
      if (Decode(data, size, &m)) (void)AddChunk(m, &texture);
      break;
    }
    case 7: {
      stage_report_t m;
      StageReport report;
      if (Decode(data, size, &m)) (void)FromMessage(m, &report);
      break;
    }
    case 8: {
      light_t m;
      ScanLight light;
      if (Decode(data, size, &m)) (void)FromMessage(m.light, &light);
      break;
    }
    case 9: {  // The projector's display-lag measurement, as it takes the camera's answers.
      latency_seen_t m;
      if (!Decode(data, size, &m)) break;
      FlashFrames f;
      f.handed_us = m.utime;
      f.white = m.index % 2 == 0;
      f.exposure_us = m.exposure_us;
      f.start_us = m.start_utime;
      f.level.assign(m.level.begin(), m.level.end());
      FlashFrames g = f;
      g.white = !f.white;
      (void)EstimateDisplayLag({f, g}, m.count);
      break;
    }
  }
  return 0;
}
