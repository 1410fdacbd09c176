<!DOCTYPE qgis PUBLIC 'http://mrcc.com/qgis.dtd' 'SYSTEM'>
<!-- Point density (points per square metre): white at zero through yellow to dark red. -->
<qgis version="3.34.0" styleCategories="Symbology">
  <pipe>
    <rasterrenderer type="singlebandpseudocolor" band="1" opacity="1" alphaBand="-1" classificationMin="@@MIN@@" classificationMax="@@MAX@@" nodataColor="">
      <rasterTransparency/>
      <rastershader>
        <colorrampshader colorRampType="INTERPOLATED" classificationMode="1" clip="0" minimumValue="@@MIN@@" maximumValue="@@MAX@@" labelPrecision="2">
          <item value="@@MIN@@" label="@@MIN@@" color="#ffffff" alpha="255"/>
          <item value="@@Q50@@" label="@@Q50@@" color="#fecc5c" alpha="255"/>
          <item value="@@Q75@@" label="@@Q75@@" color="#fd8d3c" alpha="255"/>
          <item value="@@MAX@@" label="@@MAX@@" color="#bd0026" alpha="255"/>
        </colorrampshader>
      </rastershader>
    </rasterrenderer>
    <brightnesscontrast brightness="0" contrast="0" gamma="1"/>
    <huesaturation saturation="0" colorizeOn="0" grayscaleMode="0" invertColors="0"/>
    <rasterresampler maxOversampling="2"/>
  </pipe>
  <blendMode>0</blendMode>
</qgis>
