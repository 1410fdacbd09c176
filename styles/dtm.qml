<!DOCTYPE qgis PUBLIC 'http://mrcc.com/qgis.dtd' 'SYSTEM'>
<!-- Elevation: hypsometric ramp from green lowlands to brown and white heights; the stretch
     (@@MIN@@ .. @@MAX@@) is filled in from the data's 2nd and 98th percentiles when written. -->
<qgis version="3.34.0" styleCategories="Symbology">
  <pipe>
    <provider><resampling enabled="false" zoomedInResamplingMethod="nearestNeighbour" zoomedOutResamplingMethod="nearestNeighbour" maxOversampling="2"/></provider>
    <rasterrenderer type="singlebandpseudocolor" band="1" opacity="1" alphaBand="-1" classificationMin="@@MIN@@" classificationMax="@@MAX@@" nodataColor="">
      <rasterTransparency/>
      <minMaxOrigin><limits>None</limits><extent>WholeRaster</extent><statAccuracy>Estimated</statAccuracy><cumulativeCutLower>0.02</cumulativeCutLower><cumulativeCutUpper>0.98</cumulativeCutUpper><stdDevFactor>2</stdDevFactor></minMaxOrigin>
      <rastershader>
        <colorrampshader colorRampType="INTERPOLATED" classificationMode="1" clip="0" minimumValue="@@MIN@@" maximumValue="@@MAX@@" labelPrecision="1">
          <item value="@@MIN@@" label="@@MIN@@" color="#1a9641" alpha="255"/>
          <item value="@@Q25@@" label="@@Q25@@" color="#a6d96a" alpha="255"/>
          <item value="@@Q50@@" label="@@Q50@@" color="#ffffbf" alpha="255"/>
          <item value="@@Q75@@" label="@@Q75@@" color="#d7a36a" alpha="255"/>
          <item value="@@MAX@@" label="@@MAX@@" color="#f4f0ec" alpha="255"/>
        </colorrampshader>
      </rastershader>
    </rasterrenderer>
    <brightnesscontrast brightness="0" contrast="0" gamma="1"/>
    <huesaturation saturation="0" colorizeOn="0" colorizeRed="255" colorizeGreen="128" colorizeBlue="128" colorizeStrength="100" grayscaleMode="0" invertColors="0"/>
    <rasterresampler maxOversampling="2"/>
    <resamplingStage>resamplingFilter</resamplingStage>
  </pipe>
  <blendMode>0</blendMode>
</qgis>
