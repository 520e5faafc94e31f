# Finds vdbclay's dependencies. Shared by the build and by the installed vdbclayConfig.cmake.
# Debian ships FindOpenVDB.cmake (and its helpers) outside CMake's default module path.
foreach(_dir /usr/lib/${CMAKE_LIBRARY_ARCHITECTURE}/cmake/OpenVDB /usr/lib/cmake/OpenVDB
             /usr/local/lib/cmake/OpenVDB /usr/share/OpenVDB/cmake)
  if(EXISTS "${_dir}/FindOpenVDB.cmake")
    list(APPEND CMAKE_MODULE_PATH "${_dir}")
  endif()
endforeach()
find_package(OpenVDB REQUIRED)
find_package(TBB REQUIRED)
find_package(PNG REQUIRED)
