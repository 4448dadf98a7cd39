// props.json: the studio's file reads back as the studio's crate; the box generator reproduces it;
// bad files (issue 6 item 5: duplicate tag ids across props, negative sizes, unknown family, and
// the rest of the validation) fail with errors that name the file, the prop and the field.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/io.h"
#include "datasets/studio.h"
#include "scratch.h"
#include "studio_fixture.h"
#include "tracking/props.h"

namespace previz::tracking {
namespace {

nlohmann::json twoProps() {
  PropSet set;
  BoxPropOptions a;
  set.props.push_back(makeBoxProp(a));
  PlatePropOptions b;
  b.prop_id = 1;
  b.first_tag_id = 10;
  b.rows = 1;
  b.cols = 2;
  b.width_m = 0.3;
  b.height_m = 0.15;
  set.props.push_back(makePlateProp(b));
  return propsToJson(set);
}

std::string errorOf(const nlohmann::json& j, const std::string& file = "props.json") {
  try {
    propsFromJson(j, file);
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

TEST(Props, BoxGeneratorReproducesTheStudioCrate) {
  const synth::Studio studio{synth::StudioConfig{}};
  const PropDef truth = test::studioProps(studio).props[0];
  const PropDef box = makeBoxProp(BoxPropOptions{});
  ASSERT_EQ(box.tags.size(), truth.tags.size());
  for (size_t k = 0; k < box.tags.size(); ++k) {
    EXPECT_EQ(box.tags[k].id, truth.tags[k].id);
    EXPECT_EQ(box.tags[k].size_m, truth.tags[k].size_m);
    EXPECT_LT((box.tags[k].T_prop_tag.matrix() - truth.tags[k].T_prop_tag.matrix()).cwiseAbs().maxCoeff(), 1e-15);
  }
}

TEST(Props, RoundTripThroughFileIsExact) {
  const auto dir = previz::test::scratchDir("tracking", "props_roundtrip");
  const PropSet set = propsFromJson(twoProps());
  writeProps(set, dir / "props.json");
  const PropSet back = readProps(dir / "props.json");
  ASSERT_EQ(back.props.size(), 2u);
  EXPECT_EQ(back.props[1].tags.size(), 2u);
  EXPECT_EQ(back.props[1].shape, "plate");
  EXPECT_EQ(propsToJson(back), propsToJson(set));
  // Corners: the tag frame's (-s/2, s/2, 0) first, as libapriltag's p[0].
  const TagDef& t = back.props[1].tags[0];
  EXPECT_LT((t.cornersInProp()[0] - Eigen::Vector3d(-0.075 - 0.06, 0.06, 0)).norm(), 1e-12);
  ASSERT_TRUE(back.findTag("tag36h11", 11));
  EXPECT_EQ(back.findTag("tag36h11", 11)->first, 1);
  EXPECT_FALSE(back.findTag("tag36h11", 99));
  EXPECT_FALSE(back.findTag("tag25h9", 0));
}

TEST(Props, DuplicateTagIdsAcrossPropsAreRejected) {
  nlohmann::json j = twoProps();
  j["props"][1]["tags"][0]["id"] = 3;  // the crate's tag 3
  const std::string e = errorOf(j);
  EXPECT_NE(e.find("props.json"), std::string::npos) << e;
  EXPECT_NE(e.find("duplicate tag tag36h11 id 3"), std::string::npos) << e;
  EXPECT_NE(e.find("'crate'"), std::string::npos) << e;
  EXPECT_NE(e.find("'plate'"), std::string::npos) << e;
  EXPECT_NE(e.find("props[1].tags[0].id"), std::string::npos) << e;
  // The same id in another family is another tag.
  j["props"][1]["tags"][0]["family"] = "tag25h9";
  EXPECT_EQ(errorOf(j), "");
}

TEST(Props, NegativeSizesAreRejected) {
  nlohmann::json j = twoProps();
  j["props"][0]["tags"][2]["size_m"] = -0.12;
  std::string e = errorOf(j);
  EXPECT_NE(e.find("size_m must be > 0 (got -0.12)"), std::string::npos) << e;
  EXPECT_NE(e.find("props[0].tags[2].size_m"), std::string::npos) << e;
  j = twoProps();
  j["props"][0]["tags"][0]["size_m"] = 0;
  EXPECT_NE(errorOf(j).find("size_m must be > 0"), std::string::npos);
  j = twoProps();
  j["props"][0]["box_size_m"] = {0.3, -0.3, 0.3};
  e = errorOf(j);
  EXPECT_NE(e.find("box_size_m"), std::string::npos) << e;
}

TEST(Props, UnknownFamilyIsRejected) {
  nlohmann::json j = twoProps();
  j["props"][0]["tags"][1]["family"] = "tag37h11";
  const std::string e = errorOf(j);
  EXPECT_NE(e.find("unknown AprilTag family 'tag37h11'"), std::string::npos) << e;
  EXPECT_NE(e.find("tag36h11"), std::string::npos) << e;  // lists what exists
  EXPECT_NE(e.find("props[0].tags[1].family"), std::string::npos) << e;
}

TEST(Props, OtherMalformedFilesNameTheField) {
  nlohmann::json j = twoProps();
  j["props"][1]["id"] = 0;
  EXPECT_NE(errorOf(j).find("duplicate prop id 0"), std::string::npos);
  j = twoProps();
  j["props"][0]["tags"][0].erase("T_prop_tag");
  EXPECT_NE(errorOf(j).find("props[0].tags[0].T_prop_tag"), std::string::npos);
  j = twoProps();
  j["props"][0]["tags"][0]["id"] = "three";
  EXPECT_NE(errorOf(j).find("expected an integer, got string"), std::string::npos);
  j = twoProps();
  j["props"][0]["tags"] = nlohmann::json::array();
  EXPECT_NE(errorOf(j).find("has no tags"), std::string::npos);
  EXPECT_NE(errorOf(nlohmann::json::array()).find("expected a props object"), std::string::npos);
  // A missing file names itself.
  try {
    readProps("/nonexistent/props.json");
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("/nonexistent/props.json"), std::string::npos);
  }
}

TEST(Props, GeneratorsRejectBadOptions) {
  BoxPropOptions b;
  b.tag_size_m = -1;
  EXPECT_THROW(makeBoxProp(b), Error);
  b = {};
  b.tag_size_m = 0.4;  // larger than the 0.3 m faces
  EXPECT_THROW(makeBoxProp(b), Error);
  b = {};
  b.faces = {"+x", "+x"};
  EXPECT_THROW(makeBoxProp(b), Error);
  b = {};
  b.family = "nope";
  EXPECT_THROW(makeBoxProp(b), Error);
  PlatePropOptions p;
  p.cols = 3;  // 3 x 0.12 m on a 0.3 m plate
  EXPECT_THROW(makePlateProp(p), Error);
}

TEST(Props, TagSheetsAreWrittenAtSize) {
  const auto dir = previz::test::scratchDir("tracking", "sheets");
  PropSet set;
  set.props.push_back(makeBoxProp(BoxPropOptions{}));
  const auto sheets = writeTagSheets(set, dir, 300);
  ASSERT_EQ(sheets.size(), 5u);
  const cv::Mat png = readImage(dir / sheets[0].png_name);
  // 10 cells of 12 mm / 8 + one extra cell each side + 2 cm: (12 * 1.5 + 20) mm at 300 dpi.
  const double expected_px = (0.12 / 8 * 12 + 0.02) / 0.0254 * 300;
  EXPECT_NEAR(png.cols, expected_px, 1.0);
  EXPECT_NE(readTextFile(dir / sheets[0].svg_name).find("mm\""), std::string::npos);
}

}  // namespace
}  // namespace previz::tracking
