// An independent ROS 1 publisher for the tests, built against Debian's roscpp (libroscpp-dev,
// libsensor-msgs-dev) by tests/src/lib.rs (`roscpp_publisher`).
//
//   ros1_cpp_pub TOPIC COUNT RATE_HZ WIDTH HEIGHT ENCODING STAMP_BASE
//
// Waits for one subscriber, then publishes COUNT sensor_msgs/Image messages at RATE_HZ with
// stamps STAMP_BASE + k seconds, k * 1000 + 7 ns and roscpp's own header seq; prints one JSON
// line per message: {"seq": S, "sec": ..., "nsec": ..., "t_ns": CLOCK_MONOTONIC at publish}.
#include <ros/ros.h>
#include <sensor_msgs/Image.h>

#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <string>

static long long monotonic_ns() {
  timespec t;
  clock_gettime(CLOCK_MONOTONIC, &t);
  return (long long)t.tv_sec * 1000000000LL + t.tv_nsec;
}

int main(int argc, char** argv) {
  ros::init(argc, argv, "perturb_test_cpp_pub", ros::init_options::AnonymousName);
  if (argc < 8) {
    std::fprintf(stderr, "usage: ros1_cpp_pub TOPIC COUNT RATE_HZ WIDTH HEIGHT ENCODING STAMP_BASE\n");
    return 2;
  }
  const std::string topic = argv[1];
  const int count = std::atoi(argv[2]);
  const double rate = std::atof(argv[3]);
  const int width = std::atoi(argv[4]);
  const int height = std::atoi(argv[5]);
  const std::string encoding = argv[6];
  const int stamp_base = std::atoi(argv[7]);
  ros::NodeHandle nh;
  ros::Publisher pub = nh.advertise<sensor_msgs::Image>(topic, count + 1);
  const ros::WallTime give_up = ros::WallTime::now() + ros::WallDuration(30.0);
  while (pub.getNumSubscribers() < 1 && ros::ok() && ros::WallTime::now() < give_up) {
    ros::WallDuration(0.02).sleep();
  }
  std::printf("{\"ready\": true}\n");
  std::fflush(stdout);
  // Bytes per pixel from the encoding's bit depth and channels (the tests use 8-bit ones).
  int bpp = 3;
  if (encoding == "mono8" || encoding.rfind("bayer_", 0) == 0) bpp = 1;
  if (encoding == "yuv422" || encoding == "yuv422_yuy2" || encoding == "mono16") bpp = 2;
  if (encoding == "rgba8" || encoding == "bgra8") bpp = 4;
  ros::WallRate r(rate);
  for (int k = 0; k < count && ros::ok(); ++k) {
    sensor_msgs::Image m;
    m.header.stamp = ros::Time(stamp_base + k, 1000 * k + 7);
    m.header.frame_id = "cpp_camera";
    m.height = height;
    m.width = width;
    m.encoding = encoding;
    m.is_bigendian = 0;
    m.step = width * bpp;
    m.data.resize((size_t)m.step * height);
    for (size_t i = 0; i < m.data.size(); ++i) m.data[i] = (uint8_t)((i * 13 + k * 7) % 251);
    pub.publish(m);
    // roscpp numbers the header itself when seq is 0: it counts from 0 per publisher.
    std::printf("{\"k\": %d, \"sec\": %d, \"nsec\": %d, \"t_ns\": %lld}\n", k, stamp_base + k,
                1000 * k + 7, monotonic_ns());
    std::fflush(stdout);
    r.sleep();
  }
  // Let the last messages leave before the node goes.
  ros::WallDuration(0.5).sleep();
  return 0;
}
