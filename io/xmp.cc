#include "io/xmp.h"

#include <exiv2/exiv2.hpp>
#include <mutex>

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
    image->writeMetadata();
  } catch (const Exiv2::AnyError& e) {
    return Status::Error(path + ": cannot write its XMP metadata: " + e.what());
  }
  return Status::Ok();
}

Status ReadXmp(const std::string& path, std::map<std::string, std::string>* properties) {
  std::lock_guard<std::mutex> lock(ExivMutex());
  properties->clear();
  try {
    InitializeOnce();
    auto image = Exiv2::ImageFactory::open(path);
    image->readMetadata();
    for (const Exiv2::Xmpdatum& datum : image->xmpData()) {
      (*properties)[datum.groupName() + ":" + datum.tagName()] = datum.value().toString(0);
    }
  } catch (const Exiv2::AnyError& e) {
    return Status::Error(path + ": cannot read its XMP metadata: " + e.what());
  }
  return Status::Ok();
}

}  // namespace vellum
