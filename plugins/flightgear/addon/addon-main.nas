# wxsky add-on: puts the .wxsky file named by /addons/wxsky/file into FlightGear's scene as a
# model. FlightGear's model loader hands the unknown extension to osgDB, which finds
# osgdb_wxsky.so in OSG_LIBRARY_PATH (fgfs-with-wxsky --sky sets both). The node draws full
# screen with FlightGear's own view and projection, so where the model stands does not matter;
# it follows the aircraft so that it is never paged out.
var main = func(addon) {
    var file = getprop("/addons/wxsky/file");
    if (file == nil or file == "") {
        logprint(LOG_ALERT, "wxsky add-on: /addons/wxsky/file is not set: no sky");
        return;
    }
    logprint(LOG_INFO, "wxsky add-on: adding ", file);
    fgcommand("add-model", props.Node.new({
        "path": file,
        "latitude-deg-prop": "/position/latitude-deg",
        "longitude-deg-prop": "/position/longitude-deg",
        "elevation-ft-prop": "/position/altitude-ft",
    }));
    setprop("/addons/wxsky/added", 1);
}
