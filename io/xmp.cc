#include "io/xmp.h"

#include <lcms2.h>

#include <exiv2/exiv2.hpp>
#include <fstream>
#include <memory>
#include <mutex>
#include <sstream>

namespace vellum {
namespace {

// Exiv2's XMP toolkit keeps global state (its namespace registry, the parser): every use in
// this process goes through one lock. A scan writes a handful of files, so it never waits.
std::mutex& ExivMutex() {
  static std::mutex mutex;
  return mutex;
}

void InitializeOnce() {
  static std::once_flag once;
  std::call_once(once, [] {
    Exiv2::XmpParser::initialize();
    Exiv2::XmpProperties::registerNs(kVellumXmpNamespace, "vellum");
  });
}

void AddText(Exiv2::XmpData& xmp, const std::string& key, Exiv2::TypeId type,
             const std::string& text) {
  if (text.empty()) return;
  Exiv2::Value::AutoPtr value = Exiv2::Value::create(type);
  value->read(type == Exiv2::langAlt ? "lang=x-default " + text : text);
  xmp.add(Exiv2::XmpKey(key), value.get());
}

}  // namespace

std::string MakeSrgbProfile(int channels) {
  cmsHPROFILE profile = nullptr;
  if (channels == 3) {
    profile = cmsCreate_sRGBProfile();
  } else {
    // sRGB's transfer function (IEC 61966-2-1), as a parametric curve of type 4.
    const cmsFloat64Number srgb[5] = {2.4, 1 / 1.055, 0.055 / 1.055, 1 / 12.92, 0.04045};
    cmsToneCurve* curve = cmsBuildParametricToneCurve(nullptr, 4, srgb);
    cmsCIExyY d65;
    cmsWhitePointFromTemp(&d65, 6504);
    profile = cmsCreateGrayProfile(&d65, curve);
    cmsFreeToneCurve(curve);
    if (profile) {
      cmsMLU* description = cmsMLUalloc(nullptr, 1);
      cmsMLUsetASCII(description, "en", "US", "Gray, sRGB tone curve (vellum)");
      cmsWriteTag(profile, cmsSigProfileDescriptionTag, description);
      cmsMLUfree(description);
    }
  }
  if (!profile) return "";
  cmsSetProfileVersion(profile, 2.1);
  cmsUInt32Number size = 0;
  std::string bytes;
  if (cmsSaveProfileToMem(profile, nullptr, &size) && size > 0) {
    bytes.resize(size);
    if (!cmsSaveProfileToMem(profile, bytes.data(), &size)) bytes.clear();
  }
  cmsCloseProfile(profile);
  // The header's creation date (bytes 24 to 35) is the time Little CMS made it; a fixed one
  // keeps the files vellum writes the same from run to run (2024-01-01 00:00:00).
  if (bytes.size() >= 128) {
    const uint16_t date[6] = {2024, 1, 1, 0, 0, 0};
    for (int k = 0; k < 6; ++k) {
      bytes[24 + 2 * k] = static_cast<char>(date[k] >> 8);
      bytes[25 + 2 * k] = static_cast<char>(date[k] & 0xff);
    }
  }
  return bytes;
}

Status ParseIccProfile(const std::string& bytes, const std::string& where, IccProfile* profile) {
  *profile = IccProfile();
  cmsHPROFILE h = cmsOpenProfileFromMem(bytes.data(), static_cast<cmsUInt32Number>(bytes.size()));
  if (!h) return Status::Error(where + ": not an ICC profile (Little CMS cannot read it)");
  const cmsColorSpaceSignature space = cmsGetColorSpace(h);
  char text[256] = "";
  cmsGetProfileInfoASCII(h, cmsInfoDescription, "en", "US", text, sizeof(text));
  cmsCloseProfile(h);
  if (space != cmsSigRgbData && space != cmsSigGrayData) {
    return Status::Error(where + ": an ICC profile of neither RGB nor gray images ('" +
                         std::string(text) + "'): a camera's profile describes one of them");
  }
  profile->bytes = bytes;
  profile->description = text;
  profile->source = where;
  profile->channels = space == cmsSigRgbData ? 3 : 1;
  return Status::Ok();
}

Status ReadIccFile(const std::string& path, IccProfile* profile) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return Status::Error(path + ": cannot read the ICC profile");
  std::ostringstream bytes;
  bytes << in.rdbuf();
  return ParseIccProfile(bytes.str(), path, profile);
}

Status WriteXmp(const std::string& path, const XmpFields& fields) {
  std::lock_guard<std::mutex> lock(ExivMutex());
  try {
    InitializeOnce();
    auto image = Exiv2::ImageFactory::open(path);
    image->readMetadata();
    Exiv2::XmpData& xmp = image->xmpData();
    const ScanIdentity& id = fields.identity;
    AddText(xmp, "Xmp.dc.identifier", Exiv2::xmpText, id.shelfmark);
    AddText(xmp, "Xmp.dc.title", Exiv2::langAlt, IdentityTitle(id));
    AddText(xmp, "Xmp.dc.description", Exiv2::langAlt, id.note);
    AddText(xmp, "Xmp.dc.contributor", Exiv2::xmpBag, id.operator_name);
    ForEachIdentityField(id, [&](const char* key, const std::string& value) {
      AddText(xmp, std::string("Xmp.vellum.") + key, Exiv2::xmpText, value);
    });
    for (const auto& [key, value] : fields.figures) {
      AddText(xmp, "Xmp.vellum." + key, Exiv2::xmpText, value);
    }
    AddText(xmp, "Xmp.xmp.CreatorTool", Exiv2::xmpText, fields.creator_tool);
    if (fields.icc_channels == 1 || fields.icc_channels == 3) {
      const IccProfile& given = fields.icc_profile;
      if (!given.empty() && given.channels != fields.icc_channels) {
        return Status::Error(path + ": the ICC profile '" + given.description + "' describes " +
                             (given.channels == 3 ? "colour" : "gray") + " images, this one is " +
                             (fields.icc_channels == 3 ? "colour" : "gray"));
      }
      const std::string icc = given.empty() ? MakeSrgbProfile(fields.icc_channels) : given.bytes;
      if (icc.empty()) return Status::Error(path + ": cannot make its ICC profile");
      Exiv2::DataBuf buffer(reinterpret_cast<const Exiv2::byte*>(icc.data()),
                            static_cast<long>(icc.size()));
      image->setIccProfile(buffer, true);
    }
    image->writeMetadata();
  } catch (const Exiv2::AnyError& e) {
    return Status::Error(path + ": cannot write its XMP metadata: " + e.what());
  }
  return Status::Ok();
}

// Opens the file's metadata under the lock and hands it to `read`; an error names the file and
// `what` was being read.
template <class Read>
Status ReadMetadata(const std::string& path, const char* what, Read&& read) {
  std::lock_guard<std::mutex> lock(ExivMutex());
  try {
    InitializeOnce();
    auto image = Exiv2::ImageFactory::open(path);
    image->readMetadata();
    read(*image);
  } catch (const Exiv2::AnyError& e) {
    return Status::Error(path + ": cannot read its " + what + ": " + e.what());
  }
  return Status::Ok();
}

Status ReadXmp(const std::string& path, std::map<std::string, std::string>* properties) {
  properties->clear();
  return ReadMetadata(path, "XMP metadata", [&](Exiv2::Image& image) {
    for (const Exiv2::Xmpdatum& datum : image.xmpData()) {
      (*properties)[datum.groupName() + ":" + datum.tagName()] = datum.value().toString(0);
    }
  });
}

Status ReadIccProfile(const std::string& path, std::string* profile) {
  profile->clear();
  return ReadMetadata(path, "ICC profile", [&](Exiv2::Image& image) {
    if (!image.iccProfileDefined()) return;
    const Exiv2::DataBuf* icc = image.iccProfile();
    profile->assign(reinterpret_cast<const char*>(icc->pData_), icc->size_);
  });
}

}  // namespace vellum
