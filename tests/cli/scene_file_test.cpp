// The TOML scene file of `lapflow bake scene.toml`: each key becomes one
// `--key=value` argument; anything that is not an option is an InputError
// naming the file and the line.
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "lapflow/core/errors.hpp"
#include "scene_file.hpp"

using lapflow::InputError;
using lapflow::cli::scene_text_arguments;

TEST(SceneFile, KeysBecomeOptionsAndPathsResolveBesideTheFile) {
  const std::vector<std::string> args = scene_text_arguments(
      "mesh = \"m.%04d.ply\"\nradius = 1.25e-7\nallow_zero_velocity = true\n[bake]\nframes = \"1-4\"\n",
      "shots/a/scene.toml");
  // Keys come in name order; a float keeps every digit.
  const std::vector<std::string> want = {"--allow-zero-velocity", "--mesh=shots/a/m.%04d.ply", "--radius=1.25e-07",
                                         "--frames=1-4"};
  EXPECT_EQ(args, want);
}

TEST(SceneFile, AKeyThatIsNoOptionNameIsAnErrorNamingTheFileAndLine) {
  // `"" = true` once became the argument "--" (found by fuzz_scene): CLI11
  // would have read everything after it as positional.
  for (const std::string& text : {std::string("mesh = \"a\"\n\"\" = true\n"), std::string("mesh = \"a\"\n\"x y\" = 1\n"),
                                  std::string("mesh = \"a\"\n\"r=2\" = 1\n"), std::string("mesh = \"a\"\n\"-x\" = 1\n")}) {
    try {
      scene_text_arguments(text, "shots/s.toml");
      ADD_FAILURE() << "accepted: " << text;
    } catch (const InputError& e) {
      const std::string what = e.what();
      EXPECT_EQ(e.file(), "shots/s.toml");
      EXPECT_NE(what.find("line 2"), std::string::npos) << what;
      EXPECT_NE(what.find("is not an option name"), std::string::npos) << what;
    }
  }
}
