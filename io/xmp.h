// Metadata inside image files: an XMP packet (Adobe's Extensible Metadata Platform, the
// packet libraries and image servers read) and an ICC colour profile, written into a TIFF that
// is already on disk, and read back. Written with Exiv2 (Debian's libexiv2), so the TIFF
// structure is never hand-made; the profile is made by Little CMS (liblcms2).
#pragma once

#include <map>
#include <string>

#include "core/common/status.h"
#include "core/patterns/scan.h"

namespace vellum {

// The namespace of vellum's own XMP properties (prefix "vellum"), one per identity field and
// per measured figure. The host name is reserved (RFC 2606): it names, it does not resolve.
inline constexpr const char* kVellumXmpNamespace = "http://vellum.invalid/ns/scan/1.0/";

// An ICC colour profile, checked by Little CMS: its bytes, its description (the profile's
// description tag, as exiftool's ProfileDescription says it) and the channels of the images it
// describes (3: RGB, 1: gray).
struct IccProfile {
  std::string bytes, description;
  int channels = 0;
  std::string source;  // Where it was read from (a file), for errors.
  bool empty() const { return bytes.empty(); }
};

// The profile in `bytes` (`where` names it in an error: a file, a flag): an error unless Little
// CMS reads it as a profile of RGB or gray images.
Status ParseIccProfile(const std::string& bytes, const std::string& where, IccProfile* profile);
// The profile in the file at `path` (e.g. the camera's, from its maker or a colour target).
Status ReadIccFile(const std::string& path, IccProfile* profile);

// What goes into a file's XMP packet. Dublin Core carries the catalogue identity as any
// reader expects it: dc:identifier = shelfmark, dc:title = IdentityTitle (shelfmark, folio,
// side), dc:description = note, dc:contributor = operator; vellum:<key> repeats each identity
// field as typed and adds `figures` (key -> text, e.g. "dpi" -> "400").
struct XmpFields {
  ScanIdentity identity;
  std::map<std::string, std::string> figures;
  std::string creator_tool;  // xmp:CreatorTool, e.g. "vellum 0.1.0"
  // The image's channels, for its ICC profile: 3 (colour) or 1 (gray); 0 = no profile.
  int icc_channels = 0;
  // The profile to embed (the camera's); its channels must be the image's. Empty: sRGB (a
  // colour image), or gray with sRGB's tone curve and white (a gray image).
  IccProfile icc_profile;
};

// Adds the packet (and the profile) to the image file at `path` (TIFF, PNG or JPEG), keeping
// its pixels and tags. Empty fields are left out.
Status WriteXmp(const std::string& path, const XmpFields& fields);

// The packet's properties as "prefix:name" -> value (the first value of a bag or
// language alternative), for tests and tools; an error names the file.
Status ReadXmp(const std::string& path, std::map<std::string, std::string>* properties);

// The ICC profile embedded in an image file (empty when there is none).
Status ReadIccProfile(const std::string& path, std::string* profile);

// An ICC profile (v2.1, so every reader takes it) from Little CMS: sRGB for 3 channels, gray with
// sRGB's tone curve and D65 white for 1.
std::string MakeSrgbProfile(int channels);

}  // namespace vellum
