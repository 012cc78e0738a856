// Capability names (registry.h) and the capabilities the harness derives from a scene's rigid
// objects (issue F8: contact_reaction).
#include <deform/engine/scene.h>
#include <deform/sdk/registry.h>
#include <deform_harness/runner.h>
#include <gtest/gtest.h>

#include <set>
#include <string>

namespace deform {
namespace {

TEST(Capability, EveryNameParsesBackToItsCapabilityAndNamesAreUnique) {
  std::set<std::string> names;
  for (int i = 0; i <= static_cast<int>(Capability::Sliding); ++i) {
    const auto c = static_cast<Capability>(i);
    const std::string name = capabilityName(c);
    EXPECT_TRUE(names.insert(name).second) << "duplicate name " << name;
    Capability back = Capability::Grasp;
    ASSERT_TRUE(capabilityFromName(name, back)) << name;
    EXPECT_EQ(back, c) << name;
  }
  EXPECT_STREQ(capabilityName(Capability::ContactReaction), "contact_reaction");
  Capability c = Capability::Cut;
  EXPECT_FALSE(capabilityFromName("contact reaction", c));
  EXPECT_FALSE(capabilityFromName("", c));
  EXPECT_EQ(c, Capability::Cut) << "an unknown name leaves the output alone";
}

TEST(Capability, AppendedEnumeratorsKeepTheValuesOldPluginsWereBuiltWith) {
  // ABI 2 plugins carry these values in their ModelInfo::capabilities.
  EXPECT_EQ(static_cast<int>(Capability::Grasp), 0);
  EXPECT_EQ(static_cast<int>(Capability::QuasiStatic), 7);
  EXPECT_EQ(static_cast<int>(Capability::Contact), 8);
  EXPECT_EQ(static_cast<int>(Capability::ContactReaction), 9);
  EXPECT_EQ(static_cast<int>(Capability::RollerSupport), 10);
  EXPECT_STREQ(capabilityName(Capability::RollerSupport), "roller_support");
  EXPECT_EQ(static_cast<int>(Capability::Markers), 11);
  EXPECT_STREQ(capabilityName(Capability::Markers), "markers");
  EXPECT_EQ(static_cast<int>(Capability::Sliding), 12);
  EXPECT_STREQ(capabilityName(Capability::Sliding), "sliding");
}

TEST(Capability, SlidingPlatesNeedSlidingNeverABondedHoldInSilence) {
  nlohmann::json j = nlohmann::json::parse(R"({
    "organ": {"mesh": "phantom:cube"},
    "plates": [{"region": {"box": [[-1, -1, 0.049], [1, 1, 1]]}, "contact": "sliding",
                "trajectory": [{"t": 0, "offset": [0, 0, 0]}, {"t": 1, "offset": [0, 0, -0.004]}]}],
    "models": [{"plugin": "toy"}]
  })");
  ModelInfo info;
  info.name = "toy";
  info.capabilities = {Capability::Grasp};
  const std::string why = harness::unsupportedReason(info, parseScene(j, "s.json"));
  EXPECT_NE(why.find("sliding capability"), std::string::npos) << why;
  EXPECT_NE(why.find("plate 0"), std::string::npos) << why;
  info.capabilities.push_back(Capability::Sliding);
  EXPECT_EQ(harness::unsupportedReason(info, parseScene(j, "s.json")), "");
  // A bonded plate needs grasp only.
  j["plates"][0]["contact"] = "bonded";
  info.capabilities = {Capability::Grasp};
  EXPECT_EQ(harness::unsupportedReason(info, parseScene(j, "s.json")), "");
}

TEST(Capability, RollerSupportsNeedRollerSupportNeverAFullPin) {
  nlohmann::json j = nlohmann::json::parse(R"({
    "organ": {"mesh": "phantom:cube",
              "fixed": [{"box": [[-1, -1, -1], [1, 1, -0.049]], "axes": "z"}]},
    "models": [{"plugin": "toy"}]
  })");
  ModelInfo info;
  info.name = "toy";
  const std::string why = harness::unsupportedReason(info, parseScene(j, "s.json"));
  EXPECT_NE(why.find("roller_support"), std::string::npos) << why;
  EXPECT_NE(why.find("roller supports"), std::string::npos) << why;
  info.capabilities = {Capability::RollerSupport};
  EXPECT_EQ(harness::unsupportedReason(info, parseScene(j, "s.json")), "");
  // A box holding every axis is an ordinary clamp: no capability needed.
  j["organ"]["fixed"][0]["axes"] = "zxy";
  info.capabilities.clear();
  EXPECT_EQ(harness::unsupportedReason(info, parseScene(j, "s.json")), "");
}

Scene objectScene(bool withObject) {
  nlohmann::json j = nlohmann::json::parse(R"({
    "organ": {"mesh": "phantom:cube"},
    "models": [{"plugin": "toy"}]
  })");
  if (withObject)
    j["objects"] = {{{"shape", "sphere"}, {"radius", 0.01}, {"mass", 0.002}, {"pos", {0, 0, 0.2}}}};
  return parseScene(j, "s.json");
}

TEST(Capability, RigidObjectsNeedContactReactionAndTheReasonSaysSo) {
  ModelInfo info;
  info.name = "toy";
  info.capabilities = {Capability::Contact};
  const std::string why = harness::unsupportedReason(info, objectScene(true));
  EXPECT_NE(why.find("contact_reaction"), std::string::npos) << why;
  EXPECT_NE(why.find("rigid objects"), std::string::npos) << why;
  EXPECT_NE(why.find("toy"), std::string::npos) << why;
  // Without objects the capability is not needed.
  EXPECT_EQ(harness::unsupportedReason(info, objectScene(false)), "");
  info.capabilities.push_back(Capability::ContactReaction);
  EXPECT_EQ(harness::unsupportedReason(info, objectScene(true)), "");
  // contact_reaction alone does not make up for contact.
  info.capabilities = {Capability::ContactReaction};
  EXPECT_NE(harness::unsupportedReason(info, objectScene(true)).find("contact capability"),
            std::string::npos);
}

}  // namespace
}  // namespace deform
