# deform_bullet_double: Debian's Bullet 3.24 built with BT_USE_DOUBLE_PRECISION (the *-float64
# libraries that libbullet-dev ships beside the single-precision ones). Both Bullet peers use it
# so that they integrate in double like every other model. BulletConfig.cmake only gives the
# single-precision names (BULLET_LIBRARIES) and paths relative to BULLET_ROOT_DIR, so the
# libraries are looked up by name in BULLET_ROOT_DIR/BULLET_LIBRARY_DIRS.
include_guard(GLOBAL)
if(NOT TARGET deform_bullet_double)
  set(_bt_root "${BULLET_ROOT_DIR}")
  if(NOT _bt_root)
    set(_bt_root /usr)
  endif()
  find_path(DEFORM_BULLET_INCLUDE_DIR btBulletDynamicsCommon.h
    HINTS "${_bt_root}/${BULLET_INCLUDE_DIRS}" PATH_SUFFIXES bullet)
  set(_bt_libs)
  foreach(_lib BulletSoftBody BulletDynamics BulletCollision LinearMath)
    find_library(DEFORM_BULLET_${_lib}_F64 ${_lib}-float64
      HINTS "${_bt_root}/${BULLET_LIBRARY_DIRS}")
    if(NOT DEFORM_BULLET_${_lib}_F64)
      message(FATAL_ERROR "Bullet double-precision library ${_lib}-float64 not found "
        "(install libbullet-dev, or configure with -DDEFORM_WITH_BULLET_SOFTBODY=OFF "
        "-DDEFORM_WITH_BULLET_DEFORMABLE=OFF)")
    endif()
    list(APPEND _bt_libs ${DEFORM_BULLET_${_lib}_F64})
  endforeach()
  add_library(deform_bullet_double INTERFACE)
  target_include_directories(deform_bullet_double SYSTEM INTERFACE ${DEFORM_BULLET_INCLUDE_DIR})
  target_compile_definitions(deform_bullet_double INTERFACE BT_USE_DOUBLE_PRECISION)
  target_link_libraries(deform_bullet_double INTERFACE ${_bt_libs})
  # bullet_peer_step.h: the step tail (grasps, shared instrument contact, divergence) both peers use.
  get_filename_component(_bt_common "${CMAKE_CURRENT_LIST_DIR}/../bullet_common" ABSOLUTE)
  target_include_directories(deform_bullet_double INTERFACE ${_bt_common})
endif()
