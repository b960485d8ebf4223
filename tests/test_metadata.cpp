// Metadata round trips through JSON and keeps what it does not know.
#include <gtest/gtest.h>

#include "ivol/error.hpp"
#include "ivol/metadata.hpp"

namespace {

using namespace ivol;

TEST(Metadata, RoundTripsEveryField) {
  Metadata m;
  m.voxel_size = {0.1, 0.2, 0.30000000000000004};
  m.unit = "um";
  m.origin = {-1e-9, 0, 12345.678};
  m.quantity = "density";
  m.value_unit = "g/cm^3";
  m.structure = {{"kind", "octree"}, {"lossless", false}};
  m.provenance = default_provenance();
  m.user = {{"名前", "テスト"}};
  const Metadata back = Metadata::parse(m.to_json().dump());
  EXPECT_EQ(back.voxel_size, m.voxel_size);  // exact: JSON numbers round-trip doubles
  EXPECT_EQ(back.origin, m.origin);
  EXPECT_EQ(back.unit, "um");
  EXPECT_EQ(back.value_unit, "g/cm^3");
  EXPECT_EQ(back.user, m.user);
  EXPECT_EQ(back.provenance["software"]["name"], "ivol");
  EXPECT_EQ(back.provenance["created"].get<std::string>().size(), 20u);
}

TEST(Metadata, RefusesBadValuesNamingTheKey) {
  const char* cases[][2] = {
      {R"({"voxel_size": [1,-1,1], "unit": "mm", "origin": [0,0,0], "value": {"quantity": "q"}})", "voxel_size"},
      {R"({"voxel_size": [1,1,1], "unit": 3, "origin": [0,0,0], "value": {"quantity": "q"}})", "unit"},
      {R"({"voxel_size": [1,1,1], "unit": "mm", "origin": [0,0], "value": {"quantity": "q"}})", "origin"},
      {R"({"voxel_size": [1,1,1], "unit": "mm", "origin": [0,0,0], "value": {}})", "value.quantity"},
      {R"({"voxel_size": [1,1,1], "unit": "mm", "origin": [0,0,0], "value": {"quantity": "q"}, "user": 5})", "user"},
      {R"([1, 2, 3])", "object"},
      {"\xEF\xBB\xBF{}", "byte-order mark"},
      {"{\"unit\": \"\xFF\"}", "UTF-8"},
  };
  for (const auto& c : cases) {
    try {
      Metadata::parse(c[0]);
      ADD_FAILURE() << "accepted: " << c[0];
    } catch (const Error& e) {
      EXPECT_EQ(e.error_class(), ErrorClass::Malformed);
      EXPECT_NE(std::string(e.what()).find(c[1]), std::string::npos) << e.what();
    }
  }
}

}  // namespace
