// libformat reads every conformance vector of format-spec/vectors as its
// manifest says: the dense export and levels of detail bit for bit, or the
// expected error class.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "ivol/check.hpp"
#include "ivol/reader.hpp"
#include "test_support.hpp"

namespace {

using namespace ivol;

const std::string kVectors = std::string(IVOL_SOURCE_DIR) + "/format-spec/vectors";

nlohmann::json manifest() {
  std::ifstream in(kVectors + "/manifest.json");
  return nlohmann::json::parse(in);
}

TEST(ConformanceVectors, ManifestIsPresentAndCoversBothKinds) {
  const auto m = manifest();
  std::size_t ok = 0, refused = 0;
  for (const auto& v : m["vectors"]) (v["expect"] == "ok" ? ok : refused)++;
  EXPECT_GE(ok, 10u);
  EXPECT_GE(refused, 20u);
}

TEST(ConformanceVectors, EveryVectorReadsAsExpected) {
  std::size_t checked = 0;
  const nlohmann::json all = manifest();
  for (const auto& v : all["vectors"]) {
    const std::string file = kVectors + "/" + v["file"].get<std::string>();
    const std::string expect = v["expect"];
    SCOPED_TRACE(file);
    const CheckReport report = check_file(file);
    if (expect != "ok") {
      EXPECT_FALSE(report.ok()) << "a reader must refuse it (" << expect << ")";
      if (report.ok()) continue;
      EXPECT_EQ(error_class_name(report.problems[0].error_class), expect) << report.problems[0].message;
      ++checked;
      continue;
    }
    EXPECT_TRUE(report.ok()) << report.problems[0].message;
    if (!report.ok()) continue;
    Reader reader(file);
    const auto dense = reader.read_box_bits(full_box(reader.layout().dims));
    EXPECT_EQ(dense, test::read_bytes(kVectors + "/" + v["dense"].get<std::string>()));
    if (v.contains("lod"))
      for (const auto& [level, raw] : v["lod"].items()) {
        const unsigned lod = static_cast<unsigned>(std::stoul(level));
        EXPECT_EQ(reader.read_box_bits(full_box(reader.layout().dims, lod), lod),
                  test::read_bytes(kVectors + "/" + raw.get<std::string>()))
            << "lod " << lod;
      }
    ++checked;
  }
  EXPECT_EQ(checked, all["vectors"].size());
}

}  // namespace
