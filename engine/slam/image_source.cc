#include "engine/slam/image_source.h"

#include <memory>
#include <string>
#include <utility>

#include <opencv2/imgcodecs.hpp>

#include "engine/util/check.h"

namespace omnirig::slam {

StereoFrameLoader StereoImageLoader(std::filesystem::path dir, std::vector<ImagePairNames> pairs) {
  auto shared = std::make_shared<const std::vector<ImagePairNames>>(std::move(pairs));
  return [shared, dir = std::move(dir)](int i) {
    return ReadBoth([&](int c) {
      const std::string& name = c == 0 ? (*shared)[i].cam0 : (*shared)[i].cam1;
      cv::Mat image = cv::imread((dir / name).string(), cv::IMREAD_COLOR);
      OMNIRIG_CHECK(!image.empty(), "image " << name << " cannot be read");
      return image;
    });
  };
}

}  // namespace omnirig::slam
