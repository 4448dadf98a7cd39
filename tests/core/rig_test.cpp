// rig.json: round trip and the errors a person gets for malformed files.
#include "core/rig.h"

#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/io.h"
#include "scratch.h"

namespace fs = std::filesystem;

namespace previz {
namespace {

fs::path tmpDir(const std::string& name) {
  return test::scratchDir("rig_test", name);
}

Rig sampleRig() {
  Rig rig;
  for (int i = 0; i < 3; ++i) {
    RigCamera rc;
    rc.camera.name = "w" + std::to_string(i);
    rc.camera.width = 1280;
    rc.camera.height = 720;
    rc.camera.fx = 910.25 + i;
    rc.camera.fy = 905.5;
    rc.camera.cx = 640.125;
    rc.camera.cy = 359.75;
    rc.camera.skew = 0.1 * i;
    rc.camera.dist = {-0.12, 0.034, 1e-4, -2e-4, 0.001 * i};
    rc.T_world_cam = lookAt({3.0 * std::cos(i), 3.0 * std::sin(i), 1.7}, {0, 0, 1});
    rig.cameras.push_back(rc);
  }
  rig.cameras[2].role = "main";
  return rig;
}

// Writes j to a file and returns the error message readRig gives for it.
Error readError(const nlohmann::json& j, const std::string& name) {
  const fs::path p = tmpDir("errors") / (name + ".json");
  writeJsonAtomic(p, j);
  try {
    readRig(p);
  } catch (const Error& e) {
    return e;
  }
  ADD_FAILURE() << name << ": malformed rig accepted";
  return Error("none");
}

TEST(Rig, WriteThenReadIsExact) {
  const Rig rig = sampleRig();
  const fs::path p = tmpDir("roundtrip") / "sub" / "rig.json";
  writeRig(rig, p);
  const Rig back = readRig(p);
  ASSERT_EQ(back.cameras.size(), 3u);
  for (size_t i = 0; i < 3; ++i) {
    const Camera &a = rig.cameras[i].camera, &b = back.cameras[i].camera;
    EXPECT_EQ(a.name, b.name);
    EXPECT_EQ(a.width, b.width);
    EXPECT_EQ(a.fx, b.fx);
    EXPECT_EQ(a.fy, b.fy);
    EXPECT_EQ(a.cx, b.cx);
    EXPECT_EQ(a.cy, b.cy);
    EXPECT_EQ(a.skew, b.skew);
    EXPECT_EQ(a.dist.k1, b.dist.k1);
    EXPECT_EQ(a.dist.p2, b.dist.p2);
    EXPECT_EQ(a.dist.k3, b.dist.k3);
    EXPECT_EQ(rig.cameras[i].role, back.cameras[i].role);
    EXPECT_EQ(rig.cameras[i].T_world_cam.matrix(), back.cameras[i].T_world_cam.matrix());
  }
  const nlohmann::json j = readJsonFile(p);
  EXPECT_EQ(j.at("units"), "m");
  EXPECT_EQ(j.at("pixel_origin"), "pixel (0,0) is the centre of the top-left pixel");
  EXPECT_EQ(j.at("cameras")[0].at("model"), "brown-conrady-opencv");
  EXPECT_TRUE(j.at("cameras")[0].at("distortion").contains("k3"));
  EXPECT_EQ(back.at("w2").role, "main");
  EXPECT_EQ(back.find("nope"), nullptr);
  EXPECT_THROW(back.at("nope"), Error);
}

// A rational lens writes k4 k5 k6 and reads back bit for bit; a plain lens's rig.json has no k4
// k5 k6 keys (files written before them are unchanged), and one without them reads as k4..k6 = 0.
TEST(Rig, RationalTermsRoundTripAndArePresentOnlyWhenNonZero) {
  Rig rig = sampleRig();
  rig.cameras[1].camera.dist.k4 = 2.2123456789012345;
  rig.cameras[1].camera.dist.k5 = 1.1198765432109876;
  rig.cameras[1].camera.dist.k6 = -0.0987654321098765;
  const fs::path p = tmpDir("rational") / "rig.json";
  writeRig(rig, p);
  const Rig back = readRig(p);
  for (size_t i = 0; i < 3; ++i) EXPECT_EQ(back.cameras[i].camera.dist, rig.cameras[i].camera.dist) << i;
  const nlohmann::json j = readJsonFile(p);
  EXPECT_FALSE(j.at("cameras")[0].at("distortion").contains("k4"));
  EXPECT_EQ(j.at("cameras")[1].at("distortion").at("k6"), -0.0987654321098765);
  EXPECT_EQ(j.at("cameras")[1].at("model"), "brown-conrady-opencv");
}

TEST(Rig, MissingFieldNamesFileCameraAndField) {
  nlohmann::json j = rigToJson(sampleRig());
  j["cameras"][1].erase("fx");
  const Error e = readError(j, "missing_fx");
  EXPECT_NE(e.context().file.find("missing_fx.json"), std::string::npos);
  EXPECT_EQ(e.context().camera, "w1");
  EXPECT_EQ(e.context().field, "cameras[1].fx");
  EXPECT_NE(std::string(e.what()).find("missing"), std::string::npos) << e.what();
  EXPECT_NE(std::string(e.what()).find("a number"), std::string::npos) << e.what();
}

TEST(Rig, WrongTypeSaysWhatWasExpected) {
  nlohmann::json j = rigToJson(sampleRig());
  j["cameras"][0]["width"] = "1280";
  const Error e = readError(j, "wrong_type");
  EXPECT_EQ(e.context().field, "cameras[0].width");
  EXPECT_NE(std::string(e.what()).find("expected an integer, got string"), std::string::npos) << e.what();
  j = rigToJson(sampleRig());
  j["cameras"][2]["T_world_cam"]["t"][1] = nullptr;
  const Error e2 = readError(j, "wrong_type_pose");
  EXPECT_EQ(e2.context().field, "cameras[2].T_world_cam.t[1]");
  EXPECT_EQ(e2.context().camera, "w2");
}

TEST(Rig, NonPositiveFocalLengthIsRejected) {
  nlohmann::json j = rigToJson(sampleRig());
  j["cameras"][1]["fx"] = 0.0;
  const Error e = readError(j, "zero_fx");
  EXPECT_EQ(e.context().field, "cameras[1].fx");
  EXPECT_EQ(e.context().camera, "w1");
  EXPECT_NE(std::string(e.what()).find("> 0"), std::string::npos) << e.what();
}

TEST(Rig, DuplicateCameraNameIsRejected) {
  nlohmann::json j = rigToJson(sampleRig());
  j["cameras"][2]["name"] = "w0";
  const Error e = readError(j, "duplicate");
  EXPECT_EQ(e.context().field, "cameras[2].name");
  EXPECT_EQ(e.context().camera, "w0");
  EXPECT_NE(std::string(e.what()).find("duplicate"), std::string::npos);
  Rig rig = sampleRig();
  rig.cameras[1].camera.name = "w0";
  EXPECT_THROW(rig.validate(), Error);
  EXPECT_THROW(writeRig(rig, tmpDir("dup") / "rig.json"), Error);
  EXPECT_FALSE(fs::exists(tmpDir("dup") / "rig.json"));
}

TEST(Rig, NotJsonAndMissingFileNameTheFile) {
  const fs::path dir = tmpDir("not_json");
  writeFileAtomic(dir / "rig.json", "cameras: [w0, w1]\n");
  try {
    readRig(dir / "rig.json");
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.context().file, (dir / "rig.json").string());
    EXPECT_NE(std::string(e.what()).find("not valid JSON"), std::string::npos) << e.what();
  }
  try {
    readRig(dir / "absent.json");
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.context().file, (dir / "absent.json").string());
    EXPECT_NE(std::string(e.what()).find("does not exist"), std::string::npos) << e.what();
  }
}

TEST(Rig, OtherUnitsModelsAndPixelConventionsAreRefused) {
  nlohmann::json j = rigToJson(sampleRig());
  j["units"] = "mm";
  EXPECT_EQ(readError(j, "units").context().field, "units");
  j = rigToJson(sampleRig());
  j["cameras"][0]["model"] = "mei-unified";
  EXPECT_EQ(readError(j, "model").context().field, "cameras[0].model");
  // A fisheye's terms are k1..k4: the Brown-Conrady p1 of this camera is refused by name.
  j = rigToJson(sampleRig());
  j["cameras"][0]["model"] = "kannala-brandt";
  EXPECT_EQ(readError(j, "p1").context().field, "cameras[0].distortion.p1");
  // Brown-Conrady has k4 k5 k6 (the rational terms) and nothing past them; a fisheye has no k5.
  j = rigToJson(sampleRig());
  j["cameras"][0]["distortion"]["k7"] = 0.1;
  EXPECT_EQ(readError(j, "k7").context().field, "cameras[0].distortion.k7");
  j = rigToJson(sampleRig());
  j["cameras"][0]["model"] = "kannala-brandt";
  j["cameras"][0]["distortion"] = {{"k1", 0.01}, {"k2", 0.0}, {"k3", 0.0}, {"k4", 0.0}, {"k5", 0.01}};
  EXPECT_EQ(readError(j, "kb_k5").context().field, "cameras[0].distortion.k5");
  j = rigToJson(sampleRig());
  j["pixel_origin"] = "pixel (0,0) is the top-left corner";
  EXPECT_EQ(readError(j, "origin").context().field, "pixel_origin");
  j = rigToJson(sampleRig());
  j["cameras"][1]["role"] = "hero";
  EXPECT_EQ(readError(j, "role").context().field, "cameras[1].role");
}

TEST(Rig, OptionalFieldsTakeTheirDefaults) {
  nlohmann::json j = rigToJson(sampleRig());
  for (auto& c : j["cameras"]) {
    c.erase("skew");
    c.erase("distortion");
    c.erase("model");
    c.erase("role");
  }
  j.erase("pixel_origin");
  const Rig rig = rigFromJson(j, "inline");
  EXPECT_TRUE(rig.cameras[0].camera.dist.isZero());
  EXPECT_EQ(rig.cameras[0].camera.skew, 0.0);
  EXPECT_EQ(rig.cameras[2].role, "witness");
  const Camera c = cameraFromJson(cameraToJson(sampleRig().cameras[1].camera));
  EXPECT_EQ(c.dist.k1, -0.12);
}

}  // namespace
}  // namespace previz
