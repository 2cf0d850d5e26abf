from django.contrib import admin

from training.models import RLModel, Track, Vehicle


@admin.register(Track)
class TrackAdmin(admin.ModelAdmin):
    list_display = ["display_name", "name", "difficulty", "length_m", "width_m"]
    list_filter = ["difficulty"]
    search_fields = ["name", "display_name"]


@admin.register(RLModel)
class RLModelAdmin(admin.ModelAdmin):
    list_display = ["name", "owner", "track", "status", "created_at"]
    list_filter = ["status", "track"]
    search_fields = ["name", "owner__username"]
    date_hierarchy = "created_at"
    list_select_related = ["owner", "track"]


@admin.register(Vehicle)
class VehicleAdmin(admin.ModelAdmin):
    list_display = ["name", "owner", "camera", "lidar", "shell_colour"]
    list_filter = ["camera", "lidar"]
    search_fields = ["name", "owner__username"]
