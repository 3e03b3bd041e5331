// osgdb_wxsky: any OSG application that loads NAME.wxsky gets a SkyNode for it.
#include <osgwxsky/SkyNode>

#include <osg/Notify>
#include <osgDB/FileNameUtils>
#include <osgDB/FileUtils>
#include <osgDB/Registry>

#include <fstream>
#include <sstream>

namespace {

class ReaderWriterWxsky : public osgDB::ReaderWriter {
  public:
    ReaderWriterWxsky() { supportsExtension("wxsky", "wxsky sky and clouds (plugins/osg)"); }

    const char *className() const override { return "wxsky sky node reader"; }

    ReadResult readNode(const std::string &name, const Options *options) const override {
        std::string ext = osgDB::getLowerCaseFileExtension(name);
        if (!acceptsExtension(ext))
            return ReadResult::FILE_NOT_HANDLED;
        std::string path = osgDB::findDataFile(name, options);
        if (path.empty())
            return ReadResult::FILE_NOT_FOUND;
        std::ifstream in(path.c_str());
        if (!in)
            return ReadResult::ERROR_IN_READING_FILE;
        std::stringstream text;
        text << in.rdbuf();
        if (text.str().size() > 65536) {
            OSG_WARN << "wxsky: " << path << ": larger than 64 KiB: not a .wxsky file; nothing drawn"
                     << std::endl;
            return osgwxsky::SkyNode::disabled(path + ": larger than 64 KiB").get();
        }
        osgwxsky::Settings settings;
        std::string error;
        if (!osgwxsky::parseSettings(text.str(), path, settings, error)) {
            // the application goes on; the node draws nothing
            OSG_WARN << "wxsky: " << error << "; nothing drawn" << std::endl;
            return osgwxsky::SkyNode::disabled(error).get();
        }
        return new osgwxsky::SkyNode(settings);
    }
};

} // namespace

REGISTER_OSGPLUGIN(wxsky, ReaderWriterWxsky)
