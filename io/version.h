// Which vellum made a file: the project's version and, when built from a git checkout, its commit
// ("0.1.0+g1a2b3c4d5e6f", with ".dirty" when the tree had uncommitted changes). Products record it
// (report.json's provenance, the masters' XMP), and a collection's plan takes products made by
// another build as stale (collection/collection.h). Generated at every build by
// cmake/version.cmake.
#pragma once

namespace vellum {

const char* VellumVersion();

}  // namespace vellum
