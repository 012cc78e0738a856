# deform_add_plugin(NAME SOURCES...): builds deform_NAME.so, a plugin the loader finds, linked
# against deform::sdk (the SDK with geometry and kernels, never the engine). The one function for
# in-tree plugins (plugins/CMakeLists.txt) and out-of-tree ones (find_package(deformbench)).
#
# Every plugin hides its symbols: its own template instantiations (Eigen's, above all) must bind
# inside the plugin, never to another library's copies in the global scope (libgmsh.so exports
# Eigen instantiations built with assertions on). The SDK marks the types that cross the boundary
# (exceptions) as visible.
#
# In the deformbench build tree (DEFORM_BUILD_PLUGIN_DIR set) the plugin goes to the build's
# plugin folder and is installed with deformbench; out of tree the caller installs it, into
# DEFORMBENCH_PLUGIN_DIR for the installed deformbench to find it.
function(deform_add_plugin name)
  add_library(deform_${name} MODULE ${ARGN})
  set_target_properties(deform_${name} PROPERTIES PREFIX "" CXX_VISIBILITY_PRESET hidden
    VISIBILITY_INLINES_HIDDEN ON)
  target_compile_features(deform_${name} PRIVATE cxx_std_20)
  target_link_libraries(deform_${name} PRIVATE deform::sdk)
  if(DEFORM_BUILD_PLUGIN_DIR)
    set_target_properties(deform_${name} PROPERTIES
      LIBRARY_OUTPUT_DIRECTORY ${DEFORM_BUILD_PLUGIN_DIR} INSTALL_RPATH "$ORIGIN/../..")
    install(TARGETS deform_${name} LIBRARY DESTINATION ${DEFORM_PLUGIN_INSTALL_DIR})
    set_property(GLOBAL APPEND PROPERTY DEFORM_PLUGIN_TARGETS deform_${name})
  endif()
endfunction()

# The name this package gave the function before the in-tree and out-of-tree ones became one;
# kept for plugins written then.
function(deformbench_add_plugin name)
  deform_add_plugin(${name} ${ARGN})
endfunction()
